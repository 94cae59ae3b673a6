#!/usr/bin/env python3
"""Known-answer vectors for pprz-secure, from an independent implementation.

Reproduces, with Python's `cryptography` package (X25519, Ed25519 from an RFC 8032 seed,
ChaCha20-Poly1305) and `hashlib` (SHA-512), a whole handshake between the ground
(initiator A, id 0) and aircraft 7 (responder B), and data frames in both directions,
byte for byte as they go on the wire (PPRZ v2 frames with the secure crypto byte).

Inputs are fixed: the long-term seeds and the ephemeral keys (as each end draws them
from its RNG) are SHA-256 of fixed labels. Run it from anywhere:

    python3 -m venv /tmp/kat && /tmp/kat/bin/pip install cryptography
    /tmp/kat/bin/python secure/kat/generate.py

It rewrites `vectors.txt` (next to this script) and `../keys/INSECURE-TEST-ONLY.keys`
(the long-term keys used here, published for tests and simulation). The Rust tests
(`secure/tests/kat.rs`) read `vectors.txt` and must reproduce every byte.

Format of vectors.txt: `name = hex` lines (`#` comments); names are listed below.
"""

import hashlib
import os
import struct

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PrivateKey, X25519PublicKey
from cryptography.hazmat.primitives.ciphers.aead import ChaCha20Poly1305

HERE = os.path.dirname(os.path.abspath(__file__))

AC_ID = 7
GROUND = 0
TELEMETRY, DATALINK = 1, 2
KEY_EXCHANGE_GCS = (DATALINK, 159)
KEY_EXCHANGE_UAV = (TELEMETRY, 239)
P_AE, P_BE, SIG = 0, 1, 2
ENCRYPTED, PLAINTEXT = 0x55, 0xAA
RAW = serialization.Encoding.Raw
RAW_PUB = serialization.PublicFormat.Raw


def label(text):
    return hashlib.sha256(("pprz-secure KAT: " + text).encode()).digest()


def pprz_frame(data):
    """99 | LEN | DATA | CK_A CK_B, LEN = whole frame, sums over LEN..DATA."""
    length = len(data) + 4
    assert length <= 255
    ck_a = ck_b = 0
    for b in bytes([length]) + data:
        ck_a = (ck_a + b) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return bytes([0x99, length]) + data + bytes([ck_a, ck_b])


def v2_data(src, dst, msg, fields, component=0):
    cls, msg_id = msg
    return bytes([src, dst, (component << 4) | cls, msg_id]) + fields


def plaintext_frame(src, dst, msg, fields):
    return pprz_frame(bytes([PLAINTEXT]) + v2_data(src, dst, msg, fields))


def encrypted_frame(key, salt, counter, src, dst, msg, fields, component=0):
    nonce = struct.pack(">I", counter) + salt[4:12]
    inner = v2_data(src, dst, msg, fields, component)[2:]  # comp<<4|class, id, fields
    sealed = ChaCha20Poly1305(key).encrypt(nonce, inner, bytes([src, dst]))  # ct || tag
    return pprz_frame(bytes([ENCRYPTED]) + struct.pack(">I", counter) + bytes([src, dst]) + sealed)


def kx_gcs(ac_id, msg_type, data):
    return bytes([ac_id, msg_type, len(data)]) + data


def kx_uav(msg_type, data):
    return bytes([msg_type, len(data)]) + data


def main():
    out = []

    def put(name, value):
        if isinstance(value, int):
            value = struct.pack(">I", value)
        out.append(f"{name} = {value.hex()}")

    # Long-term keys.
    gcs_seed, uav_seed = label("GCS long-term seed"), label("UAV long-term seed")
    gcs = Ed25519PrivateKey.from_private_bytes(gcs_seed)
    uav = Ed25519PrivateKey.from_private_bytes(uav_seed)
    gcs_public = gcs.public_key().public_bytes(RAW, RAW_PUB)
    uav_public = uav.public_key().public_bytes(RAW, RAW_PUB)

    # Ephemeral keys, as each end draws them (32 bytes from its RNG).
    a_eph, b_eph = label("ground ephemeral"), label("aircraft ephemeral")
    a = X25519PrivateKey.from_private_bytes(a_eph)
    b = X25519PrivateKey.from_private_bytes(b_eph)
    p_ae = a.public_key().public_bytes(RAW, RAW_PUB)
    p_be = b.public_key().public_bytes(RAW, RAW_PUB)
    z = b.exchange(X25519PublicKey.from_public_bytes(p_ae))
    assert z == a.exchange(X25519PublicKey.from_public_bytes(p_be))
    ha = hashlib.sha512(z + b"\x00").digest()
    hb = hashlib.sha512(z + b"\x01").digest()
    ka, sa = ha[:32], ha[32:44]
    kb, sb = hb[:32], hb[32:44]

    # Message 1: ground -> aircraft, P_ae. Ours carries the aircraft id in `ac_id`;
    # Paparazzi's ground leaves it at 0 (both must be accepted).
    msg1 = plaintext_frame(GROUND, AC_ID, KEY_EXCHANGE_GCS, kx_gcs(AC_ID, P_AE, p_ae))
    msg1_ref = plaintext_frame(GROUND, AC_ID, KEY_EXCHANGE_GCS, kx_gcs(0, P_AE, p_ae))
    # Message 2: aircraft -> ground, P_be || AEAD(Kb, Sb, sign(UAV, P_be || P_ae)).
    sig_b = uav.sign(p_be + p_ae)
    msg2_data = p_be + ChaCha20Poly1305(kb).encrypt(sb, sig_b, b"")
    assert len(msg2_data) == 112
    msg2 = plaintext_frame(AC_ID, GROUND, KEY_EXCHANGE_UAV, kx_uav(P_BE, msg2_data))
    # Message 3: ground -> aircraft, AEAD(Ka, Sa, sign(GCS, P_ae || P_be)).
    sig_a = gcs.sign(p_ae + p_be)
    msg3_data = ChaCha20Poly1305(ka).encrypt(sa, sig_a, b"")
    assert len(msg3_data) == 80
    msg3 = plaintext_frame(GROUND, AC_ID, KEY_EXCHANGE_GCS, kx_gcs(AC_ID, SIG, msg3_data))

    out.append("# generated by generate.py (Python `cryptography`); do not edit")
    out.append("# long-term keys (also ../keys/INSECURE-TEST-ONLY.keys)")
    put("gcs_seed", gcs_seed)
    put("gcs_public", gcs_public)
    put("uav_seed", uav_seed)
    put("uav_public", uav_public)
    out.append("# handshake of aircraft 7 with the ground")
    put("a_eph", a_eph)
    put("p_ae", p_ae)
    put("b_eph", b_eph)
    put("p_be", p_be)
    put("z", z)
    put("ka", ka)
    put("sa", sa)
    put("kb", kb)
    put("sb", sb)
    put("sig_b", sig_b)
    put("sig_a", sig_a)
    put("msg1_wire", msg1)
    put("msg1_ref_wire", msg1_ref)
    put("msg2_wire", msg2)
    put("msg3_wire", msg3)

    # Data frames. Uplink (ground -> aircraft) under Ka/Sa, downlink under Kb/Sb; each
    # direction's counter starts at 1. `_plain` is the plain PPRZ v2 frame (what the
    # sender queues and what the receiver gets back), `_wire` the encrypted frame.
    frames = []
    ping = (GROUND, AC_ID, (DATALINK, 8), b"", 0)
    setting = (GROUND, AC_ID, (DATALINK, 4), bytes([3, AC_ID]) + struct.pack("<f", 1.5), 0)
    pong = (AC_ID, GROUND, (TELEMETRY, 3), b"", 0)
    alive = (AC_ID, GROUND, (TELEMETRY, 2), bytes([3, 0, 1, 2]), 0)
    big = (AC_ID, 0xFF, (TELEMETRY, 100), bytes(i & 0xFF for i in range(226)), 5)
    frames.append(("up1", ka, sa, 1, ping))
    frames.append(("up2", ka, sa, 2, setting))
    frames.append(("down1", kb, sb, 1, pong))
    frames.append(("down2", kb, sb, 2, alive))
    frames.append(("down3", kb, sb, 3, big))
    # The counter equal to BE32(salt[0..4]) would reuse the handshake's nonce: a sender
    # skips it. Frames with the counter just after it, and with the last counter.
    reserved_a = struct.unpack(">I", sa[:4])[0]
    reserved_b = struct.unpack(">I", sb[:4])[0]
    assert 1 < reserved_a < 0xFFFFFFFF and 1 < reserved_b < 0xFFFFFFFF
    frames.append(("up_skip", ka, sa, reserved_a + 1, ping))
    frames.append(("down_skip", kb, sb, reserved_b + 1, alive))
    frames.append(("down_last", kb, sb, 0xFFFFFFFF, pong))
    out.append("# data frames")
    put("reserved_a", reserved_a)
    put("reserved_b", reserved_b)
    for name, key, salt, counter, (src, dst, msg, fields, comp) in frames:
        plain = pprz_frame(v2_data(src, dst, msg, fields, comp))
        wire = encrypted_frame(key, salt, counter, src, dst, msg, fields, comp)
        assert len(wire) == len(plain) + 21
        put(f"{name}_counter", counter)
        put(f"{name}_plain", plain)
        put(f"{name}_wire", wire)

    with open(os.path.join(HERE, "vectors.txt"), "w") as f:
        f.write("\n".join(out) + "\n")

    keys = [
        "# INSECURE TEST KEYS -- PUBLISHED IN THE pprz-secure SOURCES. NEVER FLY WITH THEM.",
        "# Anyone can read these keys: they authenticate nothing and hide nothing. For tests",
        "# and simulation only; generate your own key file for an aircraft (see the",
        "# pprz-secure README) and keep it out of version control.",
        f"GCS_PUBLIC = {gcs_public.hex()}",
        f"GCS_PRIVATE = {gcs_seed.hex()}",
        f"UAV_PUBLIC = {uav_public.hex()}",
        f"UAV_PRIVATE = {uav_seed.hex()}",
    ]
    with open(os.path.join(HERE, "..", "keys", "INSECURE-TEST-ONLY.keys"), "w") as f:
        f.write("\n".join(keys) + "\n")


if __name__ == "__main__":
    main()

//! Power cuts and corruption, with sequential-storage's mock flash: every byte written or
//! erased counts down to a cut, after which the flash is left as it was at that byte.
//!
//! For every cut point of a store of snapshot B over snapshot A: a "reboot" (new store,
//! fresh cache, new table at its defaults) loads exactly A or exactly B, never a mix,
//! never garbage, never an error; once B was seen at a cut point, every later cut point
//! gives B; and a further store of C then loads as C.

mod common;

use common::*;
use pprz_settings::sequential_storage::mock_flash::{
    MockFlashBase, MockFlashError, WriteCountCheck,
};
use pprz_settings::{LoadReport, PageCache, PersistentStore, StoreError, buffer_len};

const BUF: usize = buffer_len(8);

type Flash<const P: usize, const W: usize, const PW: usize> = MockFlashBase<P, W, PW>;
type Store<const P: usize, const W: usize, const PW: usize> =
    PersistentStore<Flash<P, W, PW>, PageCache<P>, BUF>;
type Error = StoreError<MockFlashError>;

fn erased<const P: usize, const W: usize, const PW: usize>() -> Flash<P, W, PW> {
    // Every word written once between erases (as STM32H7 flash demands), aligned buffers.
    Flash::new(WriteCountCheck::OnceOnly, None, true)
}

/// A new store over `flash`, as after a reboot.
fn open<const P: usize, const W: usize, const PW: usize>(
    flash: Flash<P, W, PW>,
) -> Store<P, W, PW> {
    Store::with_page_cache(flash, Flash::<P, W, PW>::FULL_FLASH_RANGE).unwrap()
}

fn save_on<const P: usize, const W: usize, const PW: usize>(
    flash: Flash<P, W, PW>,
    values: &[f32; K],
) -> (Flash<P, W, PW>, Result<(), Error>) {
    let mut store = open(flash);
    let result = save(&mut store, values).map(|_| ());
    (store.into_flash(), result)
}

fn load_on<const P: usize, const W: usize, const PW: usize>(
    flash: Flash<P, W, PW>,
) -> (Flash<P, W, PW>, Result<LoadReport, Error>, [f32; K]) {
    let mut store = open(flash);
    let (report, values) = load(&mut store);
    (store.into_flash(), report, values)
}

/// Bytes written and erased by an uncut store of `values` over `flash`, and whether it
/// erased a page.
fn cost<const P: usize, const W: usize, const PW: usize>(
    flash: &Flash<P, W, PW>,
    values: &[f32; K],
) -> (u32, bool) {
    let before = flash.stats_snapshot();
    let (after, result) = save_on(flash.clone(), values);
    result.unwrap();
    let delta = before.compare_to(after.stats_snapshot());
    let bytes = delta.bytes_written + delta.erases * (W * PW) as u64;
    (u32::try_from(bytes).unwrap(), delta.erases > 0)
}

/// Stores A until the next store erases a page: the next store changes pages.
fn filled_until_page_change<const P: usize, const W: usize, const PW: usize>() -> Flash<P, W, PW> {
    let mut flash = erased();
    let mut stores = 0;
    loop {
        let (next, result) = save_on(flash, &A);
        result.unwrap();
        flash = next;
        stores += 1;
        if cost(&flash, &B).1 {
            break;
        }
        assert!(stores < 10_000, "no page change");
    }
    // Several pages were used before the first erase.
    assert!(stores > P);
    flash
}

/// A state of the store, as a load after a reboot sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Seen {
    /// No snapshot: defaults kept.
    Nothing,
    /// The empty snapshot a clear stores: defaults kept.
    Cleared,
    /// A snapshot of these values.
    Values([f32; K]),
}

impl Seen {
    fn of(report: &LoadReport, values: [f32; K]) -> Option<Seen> {
        let seen = match (report.found, report.entries) {
            (false, _) => Seen::Nothing,
            (true, 0) => Seen::Cleared,
            (true, _) => {
                return [A, B, C]
                    .into_iter()
                    .find(|s| loaded(*s) == values)
                    .map(Seen::Values);
            }
        };
        (values == DEFAULTS).then_some(seen)
    }
}

/// What is cut.
#[derive(Debug, Clone, Copy)]
enum Op {
    Save([f32; K]),
    Clear,
    Erase,
}

fn run_op<const P: usize, const W: usize, const PW: usize>(
    flash: Flash<P, W, PW>,
    op: Op,
) -> (Flash<P, W, PW>, Result<(), Error>) {
    match op {
        Op::Save(values) => save_on(flash, &values),
        Op::Clear | Op::Erase => {
            let mut store = open(flash);
            let result = embassy_futures::block_on(async {
                match op {
                    Op::Clear => store.clear().await,
                    _ => store.erase().await,
                }
            });
            (store.into_flash(), result)
        }
    }
}

/// Bytes written and erased by `op` uncut.
fn op_cost<const P: usize, const W: usize, const PW: usize>(
    flash: &Flash<P, W, PW>,
    op: Op,
) -> u32 {
    let before = flash.stats_snapshot();
    let (after, result) = run_op(flash.clone(), op);
    result.unwrap();
    let delta = before.compare_to(after.stats_snapshot());
    u32::try_from(delta.bytes_written + delta.erases * (W * PW) as u64).unwrap()
}

/// Runs `op` over `base` cut after `cut` bytes, reboots and loads; then checks that a
/// store of C works and loads as C. Returns what the load after the cut saw.
fn cut_at<const P: usize, const W: usize, const PW: usize>(
    base: &Flash<P, W, PW>,
    op: Op,
    cut: u32,
    n: u32,
) -> Seen {
    let mut flash = base.clone();
    flash.bytes_until_shutoff = Some(cut);
    let (mut flash, result) = run_op(flash, op);
    flash.bytes_until_shutoff = None;
    match result {
        Ok(()) => assert_eq!(cut, n, "{op:?} cut at {cut} of {n} succeeded"),
        Err(StoreError::Flash(MockFlashError::EarlyShutoff(..))) => assert!(cut < n),
        Err(e) => panic!("{op:?} cut {cut}/{n}: failed with {e:?}"),
    }
    let (flash, report, values) = load_on(flash);
    let report = report.unwrap_or_else(|e| panic!("{op:?} cut {cut}/{n}: load failed: {e:?}"));
    let seen = Seen::of(&report, values)
        .unwrap_or_else(|| panic!("{op:?} cut {cut}/{n}: garbage or a mix: {values:?} {report:?}"));
    let (flash, saved) = save_on(flash, &C);
    saved.unwrap_or_else(|e| panic!("{op:?} cut {cut}/{n}: store after the cut failed: {e:?}"));
    let (_, _, values) = load_on(flash);
    assert_eq!(
        values,
        loaded(C),
        "{op:?} cut {cut}/{n}: store after the cut"
    );
    seen
}

/// The first cut point that shows the new state, and the number of cut points.
struct Cuts {
    points: u32,
    committed_at: u32,
}

/// Cuts `op` over `base` (in state `old`) at each of `points` (of the `n + 1` cut points
/// `0..=n`, given `n`): each load sees `old` or `new`, `new` from some point on.
fn cut_points<const P: usize, const W: usize, const PW: usize>(
    base: &Flash<P, W, PW>,
    op: Op,
    (old, new): (Seen, Seen),
    points: impl Fn(u32) -> Vec<u32>,
) -> Cuts {
    let n = op_cost(base, op);
    let mut committed_at = None;
    for cut in points(n) {
        let seen = cut_at(base, op, cut, n);
        match (committed_at, seen) {
            (None, s) if s == new => committed_at = Some(cut),
            (None, s) if s == old => {}
            (Some(_), s) if s == new => {}
            (at, s) => panic!("{op:?} cut {cut}/{n}: {s:?} (old {old:?}, new {new:?} from {at:?})"),
        }
    }
    Cuts {
        points: n + 1,
        committed_at: committed_at.expect("the uncut operation shows the new state"),
    }
}

fn every(n: u32) -> Vec<u32> {
    (0..=n).collect()
}

#[test]
fn cut_during_the_first_store() {
    let cuts = cut_points(
        &erased::<3, 4, 256>(),
        Op::Save(A),
        (Seen::Nothing, Seen::Values(A)),
        every,
    );
    // Page marker (4 bytes), item header (8), record (49, padded to 52; the key has no
    // bytes).
    assert_eq!(cuts.points, 4 + 8 + 52 + 1);
    // The snapshot counts once its last byte is written (the padding does not matter).
    assert_eq!(cuts.committed_at, 4 + 8 + 49);
}

#[test]
fn cut_during_a_store_over_a_snapshot() {
    let (base, stored) = save_on(erased::<3, 4, 256>(), &A);
    stored.unwrap();
    let cuts = cut_points(
        &base,
        Op::Save(B),
        (Seen::Values(A), Seen::Values(B)),
        every,
    );
    assert_eq!(cuts.points, 8 + 52 + 1);
    assert_eq!(cuts.committed_at, 8 + 49);
}

#[test]
fn cut_during_a_page_change_with_an_erase() {
    // Three pages: moving to the third page erases the first (its items are stale).
    let base = filled_until_page_change::<3, 4, 256>();
    let cuts = cut_points(
        &base,
        Op::Save(B),
        (Seen::Values(A), Seen::Values(B)),
        every,
    );
    assert!(cuts.points > 1024, "{} cut points", cuts.points);
}

#[test]
fn cut_during_a_migration_that_copies_the_snapshot() {
    // Two pages: the page to erase holds the current snapshot, which is copied first.
    let base = filled_until_page_change::<2, 4, 256>();
    let cuts = cut_points(
        &base,
        Op::Save(B),
        (Seen::Values(A), Seen::Values(B)),
        every,
    );
    // Markers, the copy of A (header and record), the erase, then B.
    assert_eq!(cuts.points, 2 * 4 + 60 + 1024 + 60 + 1);
}

#[test]
fn cut_with_32_byte_words() {
    let (base, stored) = save_on(erased::<3, 32, 64>(), &A);
    stored.unwrap();
    let ab = (Seen::Values(A), Seen::Values(B));
    let cuts = cut_points(&base, Op::Save(B), ab, every);
    // 32-byte header, key and record padded to 64.
    assert_eq!(cuts.points, 32 + 64 + 1);
    let base = filled_until_page_change::<3, 32, 64>();
    cut_points(&base, Op::Save(B), ab, every);
}

/// Every cut point of the writes; one in 61 inside a 16 KiB erase (each takes
/// milliseconds here, and the erase's bytes all behave alike: the smaller pages above
/// cut at every byte of theirs).
fn writes_and_some_erase_bytes(n: u32) -> Vec<u32> {
    (0..=n)
        .filter(|c| *c < 64 || n - *c < 128 || c % 61 == 0)
        .collect()
}

#[test]
fn cut_on_16_kib_pages() {
    // F405 sectors 1-3: 3 x 16 KiB, 4-byte words.
    let (base, stored) = save_on(erased::<3, 4, 4096>(), &A);
    stored.unwrap();
    let ab = (Seen::Values(A), Seen::Values(B));
    cut_points(&base, Op::Save(B), ab, every);
    let base = filled_until_page_change::<3, 4, 4096>();
    let cuts = cut_points(&base, Op::Save(B), ab, writes_and_some_erase_bytes);
    assert!(cuts.points > 16 * 1024);
}

#[test]
fn cut_during_a_clear() {
    let (base, stored) = save_on(erased::<3, 4, 256>(), &A);
    stored.unwrap();
    let (base, stored) = save_on(base, &B);
    stored.unwrap();
    let cuts = cut_points(&base, Op::Clear, (Seen::Values(B), Seen::Cleared), every);
    // Header and a 4-byte item (the empty record).
    assert_eq!(cuts.points, 8 + 4 + 1);
    // Over a page change too.
    let base = filled_until_page_change::<3, 4, 256>();
    cut_points(&base, Op::Clear, (Seen::Values(A), Seen::Cleared), every);
}

#[test]
fn cut_during_an_erase() {
    // An erase is a way out, not a snapshot change: a cut may leave an older snapshot
    // (or none), never garbage, and the store works again afterwards.
    for base in [
        {
            let (base, stored) = save_on(erased::<3, 4, 256>(), &A);
            stored.unwrap();
            base
        },
        filled_until_page_change::<3, 4, 256>(),
    ] {
        let (base, stored) = save_on(base, &B);
        stored.unwrap();
        let n = op_cost(&base, Op::Erase);
        assert!(n >= 3 * 1024);
        for cut in 0..=n {
            let seen = cut_at(&base, Op::Erase, cut, n);
            assert!(
                [Seen::Nothing, Seen::Values(A), Seen::Values(B)].contains(&seen),
                "cut {cut}: {seen:?}"
            );
        }
        assert_eq!(cut_at(&base, Op::Erase, n, n), Seen::Nothing);
    }
}

/// Flash holding older copies of A, then B, over more than one page.
fn a_then_b() -> Flash<3, 4, 256> {
    let mut flash = erased();
    for _ in 0..20 {
        let (next, stored) = save_on(flash, &A);
        stored.unwrap();
        flash = next;
    }
    let (flash, stored) = save_on(flash, &B);
    stored.unwrap();
    flash
}

/// What a load and then stores of C did on a corrupted flash.
#[derive(Debug, PartialEq)]
enum AfterCorruption {
    /// The load saw this; the store of C worked (and loads as C).
    Stored(Seen),
    /// The load saw this; the store of C reported this error, and a later one worked
    /// (each damaged spot of the free flash spoils one store).
    StoredOnRetry(Seen, pprz_settings::ErrorKind),
}

fn load_then_store_c(flash: Flash<3, 4, 256>) -> AfterCorruption {
    let (flash, report, values) = load_on(flash);
    let report = report.unwrap_or_else(|e| panic!("load failed: {e:?}"));
    let seen = Seen::of(&report, values)
        .unwrap_or_else(|| panic!("garbage or a mix: {values:?} {report:?}"));
    assert!(
        [Seen::Values(A), Seen::Values(B)].contains(&seen),
        "{seen:?}"
    );
    let (flash, saved) = save_on(flash, &C);
    let (flash, outcome) = match saved {
        Ok(()) => (flash, AfterCorruption::Stored(seen)),
        Err(e) => {
            let mut flash = flash;
            for attempt in 0.. {
                let (next, again) = save_on(flash, &C);
                flash = next;
                match again {
                    Ok(()) => break,
                    Err(e2) if attempt < 3 => assert_eq!(e2.kind(), e.kind()),
                    Err(e2) => panic!("stores failed {attempt} times: {e:?}, {e2:?}"),
                }
            }
            (flash, AfterCorruption::StoredOnRetry(seen, e.kind()))
        }
    };
    assert_eq!(load_on(flash).2, loaded(C), "{outcome:?}");
    outcome
}

#[test]
fn random_corruption_never_panics_and_never_mixes() {
    // Random bytes anywhere (used or erased flash, markers, headers, records): a load
    // sees B, or A when B is damaged, never an error; a store that the damage spoils
    // is reported (it reads back wrong), and storing again works.
    let base = a_then_b();
    let len = base.as_bytes().len();
    let mut rng = Rng(0x2545_f491);
    let mut tally = std::collections::BTreeMap::<String, u32>::new();
    for trial in 0..4000 {
        let mut flash = base.clone();
        for _ in 0..=rng.below(3) {
            let at = rng.below(len);
            flash.as_bytes_mut()[at] = rng.next() as u8;
        }
        let outcome =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_then_store_c(flash)))
                .unwrap_or_else(|_| panic!("trial {trial}"));
        *tally.entry(format!("{outcome:?}")).or_default() += 1;
    }
    for (outcome, count) in &tally {
        println!("{count:5} {outcome}");
    }
    let count = |o: AfterCorruption| tally.get(&format!("{o:?}")).copied().unwrap_or(0);
    assert!(count(AfterCorruption::Stored(Seen::Values(B))) > 3000);
    assert!(count(AfterCorruption::Stored(Seen::Values(A))) > 0);
}

#[test]
fn every_byte_corrupted_once() {
    // Each byte of the flash in turn, set to a value it does not hold.
    let base = a_then_b();
    let mut rng = Rng(0x1357_9bdf);
    for at in 0..base.as_bytes().len() {
        let mut flash = base.clone();
        let old = flash.as_bytes()[at];
        flash.as_bytes_mut()[at] = old ^ (1 + rng.below(255)) as u8;
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_then_store_c(flash)))
            .unwrap_or_else(|_| panic!("byte {at}"));
    }
}

//! The few devices of QEMU's `mps2-an386` the benchmark needs, polled: UART0 for the
//! report, the CMSDK APB timer 0 and SysTick as clocks, and semihosting to stop QEMU.
//!
//! Both clocks count the 25 MHz system clock down. Under `-icount shift=0` QEMU's virtual
//! clock advances 1 ns per guest instruction, so one tick is 40 instructions;
//! [`calibrate`](crate::calibrate) checks it on a loop of known length.

use core::fmt;

/// Base address of UART0 (CMSDK APB UART; QEMU `-serial` 0).
const UART0: usize = 0x4000_4000;
/// Base address of timer 0 (CMSDK APB timer, clocked by the 25 MHz system clock).
const TIMER0: usize = 0x4000_0000;
/// The system clock of the board (and so of both clocks), in Hz.
pub const SYSCLK_HZ: u32 = 25_000_000;

/// Writes `value` to the 32-bit device register at `addr`.
///
/// # Safety
/// `addr` must be an aligned device register of the mps2-an386 that may be written.
unsafe fn write_reg(addr: usize, value: u32) {
    // Safety: the caller guarantees an aligned, mapped device register; writing it has
    // no effect on Rust-visible memory.
    unsafe { core::ptr::write_volatile(addr as *mut u32, value) }
}

/// Reads the 32-bit device register at `addr`.
///
/// # Safety
/// `addr` must be an aligned device register of the mps2-an386.
unsafe fn read_reg(addr: usize) -> u32 {
    // Safety: the caller guarantees an aligned, mapped device register; reading it has
    // no effect on Rust-visible memory.
    unsafe { core::ptr::read_volatile(addr as *const u32) }
}

/// UART0, transmit only, polled.
pub struct Uart;

impl Uart {
    /// Enables UART0's transmitter (115 200 baud; QEMU does not pace the bytes).
    pub fn init() -> Self {
        // Safety: BAUDDIV (0x10) and CTRL (0x08) of UART0 are writable registers.
        unsafe {
            write_reg(UART0 + 0x10, SYSCLK_HZ / 115_200);
            write_reg(UART0 + 0x08, 1);
        }
        Uart
    }

    fn write_byte(&mut self, b: u8) {
        // Safety: STATE (0x04) and DATA (0x00) of UART0; bit 0 of STATE is "TX full".
        unsafe {
            while read_reg(UART0 + 0x04) & 1 != 0 {}
            write_reg(UART0, u32::from(b));
        }
    }
}

impl fmt::Write for Uart {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        for b in s.bytes() {
            if b == b'\n' {
                self.write_byte(b'\r');
            }
            self.write_byte(b);
        }
        Ok(())
    }
}

/// Timer 0, free-running down from `u32::MAX` at the system clock: 171 s of virtual time
/// (171 * 10^9 instructions under `-icount shift=0`) before it wraps.
pub struct Timer;

impl Timer {
    /// Starts timer 0 from `u32::MAX`, reloading `u32::MAX`, no interrupt.
    pub fn start() -> Self {
        // Safety: CTRL (0x00), VALUE (0x04) and RELOAD (0x08) of timer 0 are writable.
        unsafe {
            write_reg(TIMER0, 0);
            write_reg(TIMER0 + 0x08, u32::MAX);
            write_reg(TIMER0 + 0x04, u32::MAX);
            write_reg(TIMER0, 1);
        }
        Timer
    }

    /// The counter (counts down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        // Safety: VALUE (0x04) of timer 0.
        unsafe { read_reg(TIMER0 + 0x04) }
    }
}

/// SysTick, free-running down from 2^24 - 1 at the processor clock (the second clock of
/// the calibration).
pub struct SysTick;

impl SysTick {
    /// Starts SysTick on the processor clock, no interrupt.
    pub fn start(mut syst: cortex_m::peripheral::SYST) -> Self {
        use cortex_m::peripheral::syst::SystClkSource;
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();
        SysTick
    }

    /// The 24-bit counter (counts down).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        cortex_m::peripheral::SYST::get_current()
    }
}

/// Stops QEMU through semihosting (`SYS_EXIT`): exit status 0 if `success`, 1 otherwise.
/// Needs QEMU's `-semihosting-config enable=on,target=native`.
pub fn exit(success: bool) -> ! {
    // ADP_Stopped_ApplicationExit, ADP_Stopped_RunTimeErrorUnknown.
    let reason: u32 = if success { 0x2_0026 } else { 0x2_0023 };
    // Safety: `bkpt 0xab` is the semihosting call of Arm-M; with r0 = 0x18 (SYS_EXIT) and
    // r1 the reason code QEMU ends the emulation; it touches no memory of ours.
    unsafe {
        core::arch::asm!("bkpt #0xab", inout("r0") 0x18u32 => _, in("r1") reason, options(nostack));
    }
    loop {
        cortex_m::asm::nop();
    }
}

/// Whether QEMU's semihosting command line (`-semihosting-config ...,arg=A,arg=B`: "A B")
/// has the word `word` (`SYS_GET_CMDLINE`). False when QEMU gives none.
pub fn cmdline_has(word: &str) -> bool {
    let mut buf = [0u8; 128];
    // SYS_GET_CMDLINE's parameter block: the buffer's address and size; QEMU writes the
    // command line into the buffer and its length into the second word.
    let mut block: [u32; 2] = [buf.as_mut_ptr() as u32, buf.len() as u32];
    let status: u32;
    // Safety: `bkpt 0xab` with r0 = 0x15 (SYS_GET_CMDLINE) and r1 the address of `block`:
    // QEMU writes at most `block[1]` bytes into `buf` and the length into `block[1]`, both
    // live, writable locals of this function.
    unsafe {
        core::arch::asm!(
            "bkpt #0xab",
            inout("r0") 0x15u32 => status,
            in("r1") block.as_mut_ptr(),
            options(nostack),
        );
    }
    let len = (block[1] as usize).min(buf.len());
    status == 0
        && buf[..len]
            .split(|&b| b == b' ')
            .any(|w| w == word.as_bytes())
}

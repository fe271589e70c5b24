//! Parameter and correction changes do not hold off the control tick (issue 16 item 2): a
//! tick thread paced at the 16 kHz base tick steps the drive while a link thread sends
//! `SetParams` and `LoadCorrection` frames byte by byte. The host's critical section
//! (`common`) measures every section the link side holds in that thread's processor time;
//! one held for a tick period or more would have made the sampling interrupt miss a tick.
//! The same changes done as before (`Axis::new` and the copy of the axis inside the section)
//! are measured alongside, as the reference the new sections must stay far below.

mod common;

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use common::{RamFlash, RestingStage, LINK_SECTIONS_NS, TICK_NS};

/// The link's sections since the last call: (count, median, longest, missed ticks), where a
/// section held a tick period or more misses one tick per period.
fn take_sections() -> (usize, u64, u64, u64) {
    let mut v = std::mem::take(&mut *LINK_SECTIONS_NS.lock().unwrap());
    v.sort_unstable();
    let missed = v.iter().map(|ns| ns / TICK_NS).sum();
    (v.len(), v.get(v.len() / 2).copied().unwrap_or(0), v.last().copied().unwrap_or(0), missed)
}
use control_core::golden_vectors::{preset, ALL_FEATURES};
use control_core::params::Params;
use control_core::protocol::{encode, Request, Response};
use control_core::Axis;
use drive_application::link::OUT_BYTES;
use drive_application::Drive;

#[test]
fn no_control_tick_is_missed_during_set_params_or_load_correction() {
    let heavy = preset(ALL_FEATURES).unwrap(); // 6th-order acc/dec, eight correction sections
    let drive: &'static Drive = Box::leak(Box::new(Drive::new()));
    let mut flash = RamFlash::new();
    let mut host = drive.install::<RestingStage, _>(Params::default(), &mut flash).unwrap();
    let stop: &'static AtomicBool = Box::leak(Box::new(AtomicBool::new(false)));
    let ticker = std::thread::spawn(move || {
        let mut stage = RestingStage::default();
        let period = Duration::from_nanos(TICK_NS);
        let start = Instant::now();
        let mut k = 0u32;
        while !stop.load(Ordering::Relaxed) {
            while start.elapsed() < period * k {
                std::hint::spin_loop();
            }
            drive.tick(&mut stage);
            k += 1;
        }
        (k, stage.watchdog_feeds)
    });
    // Rounds of three changes (the last one of each: back to the defaults) until the tick
    // has run 400 times meanwhile.
    let mut changes = 0;
    let mut out = [0u8; OUT_BYTES];
    let mut answers = Vec::new();
    let ticks_before = drive.ticks();
    std::thread::scope(|s| {
        s.spawn(|| {
            common::mark_link_thread();
            while changes < 201 || changes % 3 != 0 || drive.ticks().wrapping_sub(ticks_before) < 400 {
                let n = changes;
                changes += 1;
                let request = match n % 3 {
                    0 => Request::SetParams(heavy),
                    1 => Request::LoadCorrection(heavy.correction),
                    _ => Request::SetParams(Params::default()),
                };
                let mut frame = [0u8; OUT_BYTES];
                let len = encode(&request, &mut frame).unwrap();
                for &b in &frame[..len] {
                    if let Some(m) = host.receive(b, &mut flash, &mut out) {
                        answers.push(control_core::protocol::decode::<Response>(&mut out[..m]).unwrap());
                    }
                }
            }
        });
    });
    let ticks_during = drive.ticks().wrapping_sub(ticks_before);
    let (sections, new_median, new_longest, missed) = take_sections();
    stop.store(true, Ordering::Relaxed);
    let (ticks, feeds) = ticker.join().unwrap();
    assert_eq!(answers.len(), changes);
    assert!(answers.iter().all(|r| *r == Response::Done), "every change carried out: {answers:?}");
    assert_eq!(*host.params(), Params::default(), "the last change is in force");
    assert_eq!(drive.with(|_, axis| *axis.params()).unwrap(), Params::default());
    assert!(ticks_during >= 400 && feeds == ticks as u64, "the tick ran throughout ({ticks_during} ticks)");

    // The reference: the old way, the axis built and copied inside the section.
    let mut old = Axis::new(Params::default()).unwrap();
    std::thread::scope(|s| {
        s.spawn(|| {
            common::mark_link_thread();
            for _ in 0..201 {
                critical_section::with(|_| old = std::hint::black_box(Axis::new(heavy).unwrap()));
            }
        });
    });
    let (_, old_median, old_longest, old_missed) = take_sections();
    // The measurement's own cost (two reads of the thread's clock: system calls): empty sections.
    std::thread::scope(|s| {
        s.spawn(|| {
            common::mark_link_thread();
            for _ in 0..2000 {
                critical_section::with(|_| ());
            }
        });
    });
    let (_, empty, _, _) = take_sections();
    eprintln!(
        "an empty section measures {empty} ns; {sections} link sections during {changes} changes ({ticks_during} ticks): processor time median {new_median} ns, \
         longest {new_longest} ns (tick {TICK_NS} ns), missed ticks {missed}; the old way (Axis::new inside): median \
         {old_median} ns, longest {old_longest} ns, missed {old_missed}"
    );
    assert_eq!(missed, 0, "no tick missed");
    assert!(
        new_median.saturating_sub(empty) * 10 < old_median.saturating_sub(empty),
        "the swap holds the section far shorter than building the axis inside it ({new_median} vs {old_median} ns, \
         {empty} ns of measurement)"
    );
}

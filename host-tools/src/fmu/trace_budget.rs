//! The memory a run's trace may take: a scenario or timeline whose run would need more is
//! refused when it is loaded, naming stop_time, the step and the limit (not an allocation
//! failure after the FMU started).
//!
//! A run keeps its whole trace in memory (one f64 per recorded column and communication step,
//! the time included), then writes it as CSV (about 2.5 times as many bytes as text), plots
//! it and, with `--fmpy`, has fmpy build the same table a second time. [`MAX_TRACE_BYTES`],
//! 1 GiB, keeps all of that within the memory of an ordinary workstation or CI runner: with
//! every output of the FMU (53 columns with the time, 424 bytes a step) at the default step of
//! 0.25 ms that is about 633 s of simulated time; a scenario that records a few outputs
//! (`record`) or takes a longer `step` runs for proportionally longer.

use anyhow::{bail, Result};

/// Most bytes a run's trace may hold in memory.
pub const MAX_TRACE_BYTES: f64 = (1u64 << 30) as f64;

/// Bytes per recorded value (an f64).
const VALUE_BYTES: f64 = 8.0;

/// Outputs of the FMU: what a run records when its `record` list is empty.
pub fn fmu_output_count() -> usize {
    servo_axis::variables::DECLARATIONS
        .iter()
        .filter(|d| d.causality == servo_axis::variables::Causality::Output)
        .count()
}

/// Refuse a run of `stop_time / step` communication steps whose trace of `columns` columns
/// (time and the recorded outputs) would exceed [`MAX_TRACE_BYTES`]; the error names the
/// stop time, the step, the trace's size and the longest stop time that fits.
pub fn check_trace_size(stop_time: f64, step: f64, columns: usize) -> Result<()> {
    let steps = stop_time / step;
    let row_bytes = columns as f64 * VALUE_BYTES;
    let bytes = (steps + 1.0) * row_bytes;
    if bytes > MAX_TRACE_BYTES {
        let longest = (MAX_TRACE_BYTES / row_bytes - 1.0).floor() * step;
        bail!(
            "stop_time = {stop_time} s at step = {step} s is {steps:.4e} communication steps: a trace of {columns} columns \
             (time and {} outputs, 8 bytes each a step) would take {bytes:.4e} bytes, above the {} GiB a run may keep \
             in memory: at most stop_time = {longest:.6} s at this step and these columns",
            columns - 1,
            MAX_TRACE_BYTES / (1u64 << 30) as f64,
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limit_is_the_trace_memory_and_the_message_names_it() {
        let h = 0.25e-3;
        let columns = fmu_output_count() + 1;
        // The longest stop time the message gives fits; one step more does not.
        let e = check_trace_size(1e9, h, columns).unwrap_err().to_string();
        assert!(e.contains("stop_time = 1000000000 s") && e.contains("1 GiB"), "{e}");
        let at = e.find("at most stop_time = ").unwrap() + "at most stop_time = ".len();
        let longest: f64 = e[at..].split(' ').next().unwrap().parse().unwrap();
        let rows = (longest / h).round() + 1.0;
        assert!(rows * columns as f64 * 8.0 <= MAX_TRACE_BYTES, "{longest}");
        assert!((rows + 1.0) * columns as f64 * 8.0 > MAX_TRACE_BYTES, "{longest}");
        assert!(check_trace_size(longest, h, columns).is_ok());
        assert!(check_trace_size(longest + h, h, columns).is_err());
        // A tiny step is the same explosion as a huge stop time.
        assert!(check_trace_size(0.3, 1e-12, columns).is_err());
        // Fewer columns, longer runs.
        assert!(check_trace_size(10.0 * longest, h, 3).is_ok());
    }
}

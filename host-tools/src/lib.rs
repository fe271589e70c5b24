//! Host side of the servo toolkit: experiments run against the FMU through FMI 3.0 (or a drive),
//! their measurements, reports, plots and benchmarks. The `servo` binary only dispatches to the
//! experiments' commands.
//!
//! One folder per experiment — `run` (scenarios), `sweep` (seed 000), `ident` (seed 001, with
//! `tune`), `circle` (seed 002), `accdec` (seed 003), `sequence` (seed 004), `calibrate` (the twin
//! fitted to a machine: mechanics and friction) and `autotune` (gains and filters from the
//! response, built on the mechanics model `calibrate` fits), `device` (the drive
//! link) — each with its options (`args.rs`, clap), commands (`command.rs`: their `run`),
//! measurement, report, plot, bench and its section of out/index.html (`index.rs`). `bench` holds the benches
//! that are not experiments (FMU speed, plant, firmware, robustness and fault campaigns). Shared
//! pieces: `fmu` (runner, scenario, trace, fmpy, the configuration a run gives the FMU, the
//! sweep and circle runs), `analysis` (spectral, response points, polynomials), `plot`,
//! `correction` (the response correction as the FMU and the drive take it), `page` (the
//! index page), `cli` (options every command takes). Experiments use shared pieces, never each
//! other; `index` (`servo index`) gathers their sections.

pub mod accdec;
pub mod analysis;
pub mod autotune;
pub mod bench;
pub mod calibrate;
pub mod circle;
pub mod cli;
pub mod command_line;
pub mod commission;
pub mod correction;
pub mod device;
pub mod fmu;
pub mod ident;
pub mod index;
pub mod page;
pub mod paths;
pub mod plot;
pub mod random;
pub mod run;
pub mod sequence;
pub mod sweep;
pub mod virtual_drive;

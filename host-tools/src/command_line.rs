//! The `servo` command line's definition (clap): its commands and options, in the library so
//! that the command-line reference (`servo cli-reference`, the book's `reference/cli.md`) and
//! its check are generated from the one definition the binary parses with.

use clap::{CommandFactory, Parser, Subcommand};

use crate::{
    accdec, autotune, bench, calibrate, circle, commission, device, ident, index, run, sequence, sweep, virtual_drive,
};

#[derive(Parser)]
#[command(
    name = "servo",
    version,
    about = "Servo-drive toolkit: run experiments on the servo FMU, compare with fmpy, benchmark",
    long_about = "Servo-drive toolkit.\n\nEvery command runs against the FMU the project builds \
    (target/fmu/servo_axis.fmu, made by `cargo run -p xtask -- bundle`) unless --fmu says otherwise, \
    writes its files into out/<command>/ unless --out says otherwise, prints figures as JSON with --json, \
    and exits with status 1 when a check inside it fails."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    Commission(commission::CommissionArgs),
    Run(run::args::RunArgs),
    Accdec(accdec::args::AccdecArgs),
    Sequence(sequence::args::SequenceArgs),
    Circle(circle::args::CircleArgs),
    Sweep(sweep::args::SweepArgs),
    Ident(ident::args::IdentArgs),
    Tune(ident::args::TuneArgs),
    Calibrate(calibrate::command::CalibrateArgs),
    Autotune(autotune::command::AutotuneArgs),
    Compare(run::args::CompareArgs),
    Device(device::args::DeviceArgs),
    VirtualDrive(virtual_drive::args::VirtualDriveArgs),
    Index(index::IndexArgs),
    Figures(bench::figures_page::FiguresArgs),
    /// Print this command-line reference as Markdown: every command and option (the book's
    /// docs/src/reference/cli.md; `cargo run -p xtask -- references` writes it)
    CliReference,
    /// Benchmarks: each prints its figures against their goals (worst case over the range users
    /// work in), writes them to out/bench/<bench>.json (with --out, into that folder; `servo
    /// figures` and `servo index` read them) and exits 1 when a goal is missed.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
pub enum BenchCommand {
    Commission(bench::commission_bench::CommissionBenchArgs),
    Autotune(autotune::bench::AutotuneBenchArgs),
    Calibrate(calibrate::bench::CalibrateBenchArgs),
    Robustness(bench::args::RobustnessBenchArgs),
    Firmware(bench::args::FirmwareBenchArgs),
    Fmu(bench::args::FmuBenchArgs),
    Plant(bench::args::PlantBenchArgs),
    Accdec(accdec::args::AccdecBenchArgs),
    Sequence(sequence::args::SequenceBenchArgs),
    Circle(circle::args::CircleBenchArgs),
    Sweep(sweep::args::SweepBenchArgs),
    Ident(ident::args::IdentBenchArgs),
    IdentDevice(ident::device_bench::IdentDeviceBenchArgs),
    TuneDevice(ident::tune_device_bench::TuneDeviceBenchArgs),
    FmiCampaign(bench::args::FmiCampaignArgs),
    FaultCampaign(bench::args::FaultCampaignArgs),
    Device(device::bench::DeviceBenchArgs),
    Saves(device::save_bench::SaveBenchArgs),
    #[command(hide = true)]
    AccdecProbe(accdec::args::AccdecProbeArgs),
}

/// Every command takes a negative number as an option's value (`--start -5`, `--speed -1`):
/// the value then reaches its check, which says what is wrong with it, instead of clap taking
/// it for an unknown option.
pub fn with_negative_numbers(command: clap::Command) -> clap::Command {
    command.allow_negative_numbers(true).mut_subcommands(with_negative_numbers)
}

/// The command line as `servo` parses it.
pub fn command() -> clap::Command {
    with_negative_numbers(Cli::command())
}

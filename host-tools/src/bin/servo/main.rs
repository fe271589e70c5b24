//! `servo`: experiments on the servo FMU (default) and, later, on a real drive.

use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

use host_tools::{accdec, bench, circle, device, ident, index, run, sequence, sweep, virtual_drive};

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
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Run(run::args::RunArgs),
    Accdec(accdec::args::AccdecArgs),
    Sequence(sequence::args::SequenceArgs),
    Circle(circle::args::CircleArgs),
    Sweep(sweep::args::SweepArgs),
    Ident(ident::args::IdentArgs),
    Tune(ident::args::TuneArgs),
    Compare(run::args::CompareArgs),
    Device(device::args::DeviceArgs),
    VirtualDrive(virtual_drive::args::VirtualDriveArgs),
    Index(index::IndexArgs),
    /// Print this command-line reference as Markdown: every command and option (the book's
    /// docs/src/reference/cli.md; `cargo run -p xtask -- references` writes it)
    CliReference,
    /// Benchmarks: each prints its figures against their goals (worst case over the range users
    /// work in) and exits 1 when a goal is missed.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum BenchCommand {
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
fn with_negative_numbers(command: clap::Command) -> clap::Command {
    command.allow_negative_numbers(true).mut_subcommands(with_negative_numbers)
}

fn main() -> ExitCode {
    let matches = with_negative_numbers(Cli::command()).get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let result = match &cli.command {
        Command::Run(args) => args.run(),
        Command::Accdec(args) => args.run(),
        Command::Sequence(args) => args.run(),
        Command::Circle(args) => args.run(),
        Command::Sweep(args) => args.run(),
        Command::Ident(args) => args.run(),
        Command::Tune(args) => args.run(),
        Command::Compare(args) => args.run(),
        Command::Device(args) => args.run(),
        Command::VirtualDrive(args) => args.run(),
        Command::Index(args) => args.run(),
        Command::CliReference => {
            print!("{}", host_tools::cli::markdown_reference(&with_negative_numbers(Cli::command())));
            Ok(true)
        }
        Command::Bench(BenchCommand::Robustness(args)) => args.run(),
        Command::Bench(BenchCommand::Firmware(args)) => args.run(),
        Command::Bench(BenchCommand::Fmu(args)) => args.run(),
        Command::Bench(BenchCommand::Plant(args)) => args.run(),
        Command::Bench(BenchCommand::Accdec(args)) => args.run(),
        Command::Bench(BenchCommand::Sequence(args)) => args.run(),
        Command::Bench(BenchCommand::Circle(args)) => args.run(),
        Command::Bench(BenchCommand::Sweep(args)) => args.run(),
        Command::Bench(BenchCommand::Ident(args)) => args.run(),
        Command::Bench(BenchCommand::IdentDevice(args)) => args.run(),
        Command::Bench(BenchCommand::TuneDevice(args)) => args.run(),
        Command::Bench(BenchCommand::FmiCampaign(args)) => args.run(),
        Command::Bench(BenchCommand::FaultCampaign(args)) => args.run(),
        Command::Bench(BenchCommand::Device(args)) => args.run(),
        Command::Bench(BenchCommand::Saves(args)) => args.run(),
        Command::Bench(BenchCommand::AccdecProbe(args)) => args.run(),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

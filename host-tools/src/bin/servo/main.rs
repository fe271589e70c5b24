//! `servo`: experiments on the servo FMU (default) and, later, on a real drive.

use std::process::ExitCode;

use clap::FromArgMatches;

use host_tools::command_line::{command, BenchCommand, Cli, Command};

fn main() -> ExitCode {
    let matches = command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // A bench's figures are stamped with the checkout as the run starts.
    if matches!(cli.command, Command::Bench(_)) {
        host_tools::bench::figures::Stamp::of_this_run();
    }
    let result = match &cli.command {
        Command::Commission(args) => args.run(),
        Command::Run(args) => args.run(),
        Command::Accdec(args) => args.run(),
        Command::Sequence(args) => args.run(),
        Command::Circle(args) => args.run(),
        Command::Sweep(args) => args.run(),
        Command::Ident(args) => args.run(),
        Command::Tune(args) => args.run(),
        Command::Autotune(args) => args.run(),
        Command::Calibrate(args) => args.run(),
        Command::Compare(args) => args.run(),
        Command::Device(args) => args.run(),
        Command::VirtualDrive(args) => args.run(),
        Command::Index(args) => args.run(),
        Command::Figures(args) => args.run(),
        Command::CliReference => {
            print!("{}", host_tools::cli::markdown_reference(&command()));
            Ok(true)
        }
        Command::Bench(BenchCommand::Commission(args)) => args.run(),
        Command::Bench(BenchCommand::Autotune(args)) => args.run(),
        Command::Bench(BenchCommand::Calibrate(args)) => args.run(),
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

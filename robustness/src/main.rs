//! `robustness --campaign frames|requests|stream|all [--seconds N] [--seed S] [--json]
//! [--figures FILE]`: run the campaigns and print their figures (`--figures`: also write them as
//! JSON to FILE, for `servo bench robustness`'s figure file); exit 1 when any goal (0 crashes,
//! 0 accepted-corrupt frames, 0 overflow panics, 0 refusals that changed state) is missed.

use robustness::campaigns::{run, Campaign};

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut which, mut seconds, mut seed, mut json) = (String::from("all"), 20.0f64, 0x5EED_0018u64, false);
    let mut figures_file = None;
    let usage =
        "usage: robustness [--campaign frames|requests|stream|all] [--seconds N] [--seed S] [--json] [--figures FILE]";
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().unwrap_or_else(|| fail(&format!("{name} needs a value\n{usage}")));
        match a.as_str() {
            "--campaign" => which = value("--campaign"),
            "--seconds" => {
                let v = value("--seconds");
                seconds = v.parse().unwrap_or_else(|_| fail(&format!("--seconds {v}: not a number")));
                if !(seconds.is_finite() && seconds > 0.0 && seconds <= 86_400.0) {
                    fail(&format!("--seconds must be in (0, 86400] (got {v})"));
                }
            }
            "--seed" => {
                let v = value("--seed");
                seed = v.parse().unwrap_or_else(|_| fail(&format!("--seed {v}: not an unsigned integer")));
            }
            "--json" => json = true,
            "--figures" => figures_file = Some(value("--figures")),
            _ => fail(&format!("unknown argument {a}\n{usage}")),
        }
    }
    let campaigns: Vec<Campaign> = match which.as_str() {
        "all" => vec![Campaign::Frames, Campaign::Requests, Campaign::Stream],
        other => vec![Campaign::parse(other)
            .unwrap_or_else(|| fail(&format!("unknown campaign {other}: frames, requests, stream or all")))],
    };
    let mut ok = true;
    let mut all = Vec::new();
    for c in campaigns {
        let f = run(c, seconds, seed);
        ok &= f.goals_met();
        if !json {
            println!("{f}");
        }
        all.push(f);
    }
    let array = format!("[{}]", all.iter().map(|f| f.json()).collect::<Vec<_>>().join(",\n"));
    if json {
        println!("{array}");
    }
    if let Some(file) = figures_file {
        if let Err(e) = std::fs::write(&file, &array) {
            fail(&format!("cannot write {file}: {e}"));
        }
    }
    std::process::exit(if ok { 0 } else { 1 });
}

fn fail(msg: &str) -> ! {
    eprintln!("robustness: {msg}");
    std::process::exit(2);
}

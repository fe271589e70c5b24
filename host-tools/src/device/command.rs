//! `servo device`: the drive over its serial link.

use anyhow::{bail, Context, Result};

use crate::cli::progress_bar;
use crate::device::args::DeviceArgs;
use crate::fmu::trace::Trace;
use crate::paths::default_out;

impl DeviceArgs {
    pub fn run(&self) -> Result<bool> {
        device(self)
    }
}

fn device(args: &DeviceArgs) -> Result<bool> {
    let (port, baud, timeout_ms, seconds, action, common) =
        (args.port.as_str(), args.baud, args.timeout_ms, args.seconds, &args.action, &args.common);
    use crate::device::link::{open_serial, DeviceLink};
    use control_core::protocol::{Request, Response};
    let (what, arg) = (action[0].as_str(), action.get(1));
    // Everything that can be checked before the port is opened.
    let request = match (what, arg) {
        ("hello", None) => None,
        ("telemetry", None) => Some(Request::GetTelemetry),
        ("params", None) => Some(Request::GetParams),
        ("clear-faults", None) => Some(Request::ClearFaults),
        ("start-sweep", None) => Some(Request::StartSweep),
        ("save-params", None) => Some(Request::SaveParams),
        ("stream", None) => {
            if !(seconds.is_finite() && seconds > 0.0 && seconds <= 3600.0) {
                bail!("--seconds must be between 0 and 3600 (got {seconds})");
            }
            None
        }
        ("load-correction", Some(file)) => {
            let mut frame = std::fs::read(file).with_context(|| format!("cannot read {file}"))?;
            Some(crate::device::link::correction_request(&mut frame).with_context(|| file.to_string())?)
        }
        ("load-correction", None) => bail!("load-correction needs the <axis>.corr.frame file `servo tune` wrote"),
        _ => bail!(
            "unknown action `{}`: use hello, telemetry, params, clear-faults, start-sweep, save-params, load-correction FILE or stream",
            action.join(" ")
        ),
    };
    let link = DeviceLink::new(open_serial(port, baud)?, std::time::Duration::from_millis(timeout_ms));
    let mut session = crate::device::session::DriveSession::open(link)?;
    session.summary_on_drop = true;
    let boot_params = session.boot_params;
    let answer = match (what, request) {
        ("stream", _) => {
            session.order(Request::Stream { enabled: true }, "streaming on")?;
            let pb = progress_bar("streaming", common.json);
            let started = std::time::Instant::now();
            while started.elapsed().as_secs_f64() < seconds {
                session.link.listen(std::time::Duration::from_millis(100))?;
                pb.set_position((started.elapsed().as_secs_f64() / seconds * 1000.0) as u64);
            }
            pb.finish_and_clear();
            session.order(Request::Stream { enabled: false }, "streaming off")?;
            let batches = session.take_samples();
            let dropped = batches.last().map_or(0, |b| b.dropped);
            let mut t = Trace::new(crate::device::frame_stream::SAMPLE_COLUMNS.map(String::from).to_vec());
            let rows = crate::device::frame_stream::sample_rows(&batches)
                .map_err(|e| anyhow::anyhow!("corrupt sample batch from the drive: {e}"))?;
            for r in &rows {
                t.rows.push(r);
            }
            let out = common.out.clone().unwrap_or_else(|| default_out("device"));
            crate::paths::create_out_dir(&out)?;
            let csv = out.join("stream.csv");
            t.write_csv(&csv)?;
            serde_json::json!({"samples": t.rows.len(), "dropped": dropped, "file": csv})
        }
        (_, None) => serde_json::json!({
            "hello": "ok",
            "version": control_core::protocol::VERSION,
            "boot_params": boot_params.to_string(),
        }),
        (_, Some(r)) => match session.answer(&r)? {
            Response::Telemetry(t) => serde_json::json!({"telemetry": serde_json::to_value(t)?}),
            Response::Params(p) => serde_json::json!({"params": serde_json::to_value(p)?}),
            Response::Done => serde_json::json!({"done": true}),
            Response::Saved { sequence } => serde_json::json!({"done": true, "record": sequence}),
            Response::Refused(why) => bail!("the drive refused the request: {why}"),
            Response::FrameError(e) => bail!("the drive could not read the request: {e}"),
            other => bail!("unexpected answer: {other:?}"),
        },
    };
    if common.json {
        println!("{}", serde_json::to_string_pretty(&answer)?);
    } else {
        println!("servo device {port}: {what} → {answer}");
    }
    Ok(true)
}

use control_core::golden_vectors::{VectorEvent, ALL_FEATURES};
use control_core::Mode;
use host_tools::firmware::*;
use servo_axis::simulation::UserInputs;
fn main() {
    let recs = vec![record(ALL_FEATURES, 0.1, |_| UserInputs { mode: Mode::Position, position_command: 2.0, move_speed: 50.0, ..Default::default() }, &[(0.0, VectorEvent::StartSweep)])];
    std::fs::write("/tmp/small.bin", encode(&recs)).unwrap();
}

//! The README's parameter table is the one generated from the FMU's variable table.

use host_tools::paths::workspace_root;

#[test]
fn the_readme_carries_the_generated_parameter_table() {
    let readme = std::fs::read_to_string(workspace_root().join("README.md")).unwrap();
    let table = servo_axis::model_description::markdown_table();
    assert!(table.lines().count() > 100, "every parameter and input has a row");
    assert!(
        readme.contains(&table),
        "README.md's parameter table is stale: run `cargo run -q -p xtask -- parameter-table --update-readme`"
    );
}

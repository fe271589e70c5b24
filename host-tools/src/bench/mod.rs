//! Benches that are not experiments: FMU speed, plant integration, firmware, robustness and fault campaigns.

pub mod args;
pub mod backbone_command;
pub mod campaign_command;
pub mod elf_sections;
pub mod fault_campaign;
pub mod firmware;
pub mod firmware_command;
pub mod fmi_campaign;
pub mod fmu_speed;
pub mod plant;
pub mod raw_traces;
pub mod stack_depth;

//! Benches that are not experiments: FMU speed, plant integration, firmware, robustness and fault campaigns;
//! the figures every bench writes (`figures`) and the book's page rendered from them (`figures_page`).

pub mod args;
pub mod backbone_command;
pub mod campaign_command;
pub mod commission_bench;
pub mod drawn;
pub mod elf_sections;
pub mod fault_campaign;
pub mod figures;
pub mod figures_page;
pub mod firmware;
pub mod firmware_command;
pub mod fmi_campaign;
pub mod fmu_speed;
pub mod plant;
pub mod raw_traces;
pub mod stack_depth;

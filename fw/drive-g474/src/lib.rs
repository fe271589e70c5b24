//! Servo drive firmware for NUCLEO-G474RE + X-NUCLEO-IHM08M1 around the control core: board
//! code apart from application code, as a library so that the binary and the on-target tests
//! (`fw/tests`) use the same set-up.

#![no_std]

pub mod board;
pub mod control;
pub mod link;
pub mod stack;

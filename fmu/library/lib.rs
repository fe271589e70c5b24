//! The FMU's shared library: the model of `servo-fmu` (`servo_axis`) linked as a cdylib and
//! nothing else. Its FMI 3.0 and FMI 2.0 entry points (`#[no_mangle] extern "C"` in
//! `servo_axis::fmi`) are the library's exports.
//!
//! Why a crate of its own: a crate that is both an rlib and a cdylib keeps its public
//! functions exported for Rust users, so the shared library calls them through the GOT and
//! link-time optimisation cannot internalise them. Built alone as a cdylib with
//! `--profile fmu-library` (fat LTO), everything but the entry points is internal: the step's
//! calls are direct and inlined across the model, the control core and the plant.

#![no_std]

extern crate servo_axis;

//! # refloc: global localization of one 2D laser scan against a compiled map
//!
//! `#![no_std]`, no heap. Reads a `.refdb` reference database from a byte
//! slice and answers "where am I?" for one scan, with no initial pose.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]
#![deny(unsafe_code)]

pub mod frame;
pub mod raycast;

pub use frame::{wrap_angle, MapFrame, Pose2};

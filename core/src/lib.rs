//! # hexacomp-core
//!
//! The numerics of hexacomp, after Song, Tian, Tian & Liu (2022), "Calibration of a Stewart
//! platform by designing a robust joint compensator with artificial neural networks":
//!
//! - [`geometry`]: the platform geometry (the TOML of docs/formats.md), its validation and fingerprint, and the
//!   built-in `prototype`;
//! - [`pose`]: poses in LinuxCNC's convention `R = Rz(c)·Ry(b)·Rx(a)`, twists;
//! - [`kinematics`]: allocation-free inverse kinematics and Newton forward kinematics;
//! - [`screw`]: the paper's matrices `W`, `T = W⁻ᵀ` (Eq. 3), `P` (Eq. 4) and `cond(PT)`;
//! - [`sampling`]: seeded uniform poses over the task workspace;
//! - [`network`], [`model`]: the trained networks, their normalisation and the model file;
//! - [`physical`]: the physical model (identified geometry, lead-screw curves, compliance) and
//!   its corrections as a model file holds them;
//! - [`fused`], [`activation`]: a model's serving form, its networks fused into one layer
//!   evaluated four hidden nodes at a time with a vectorisable `tanh`;
//! - [`observation`]: what an instrument measured of a configuration (targets, some perhaps not
//!   seen, or a 6-DoF pose) and its linearisation (Eq. 4);
//! - [`records`]: planned poses, measured configurations and joint corrections with their ids,
//!   independent of any file format;
//! - [`compensator`]: run-time compensation with a status per point (Eq. 19, Eq. 20);
//! - [`rigid_fit`]: the least-squares rigid transform between corresponding points (locating an
//!   instrument from fiducials), with weights and locked parameters;
//! - [`stats`]: max/mean/std summaries of pose errors (the paper's Table 2 layout);
//! - [`durable`]: files replaced whole or not at all, durable across a power loss.
//!
//! Units everywhere: millimetres; radians in code, degrees only in files and on the command line.
//! This crate does no inter-process communication and starts no threads.

#![warn(missing_docs)]

pub mod activation;
pub mod compensator;
pub mod durable;
pub mod error;
pub mod fused;
pub mod geometry;
pub mod kinematics;
pub mod model;
pub mod network;
pub mod observation;
pub mod physical;
pub mod pose;
pub mod records;
pub mod rigid_fit;
pub mod sampling;
pub mod screw;
pub mod stats;
pub mod uncertainty;

pub use error::{Error, Result};
pub use geometry::{Fiducial, Fingerprint, Geometry, LEGS, MIN_TARGETS, Workspace};
pub use kinematics::{
    ForwardOptions, LegLengths, LegStatus, forward_kinematics, inverse_kinematics,
};
pub use pose::{Pose, Twist};

//! # hexacomp-service (library)
//!
//! The compensation daemon as a library: [`Service::start`] runs one instance from
//! [`ServiceOptions`] until [`Service::stop`] or SIGINT/SIGTERM; `hexacomp-service` is a thin
//! `main` around [`cli`]. Its parts: [`serving`] (the hot path: one function that answers a
//! request into a loaned response, allocation-free, and [`serving::ServingLoop`], whose
//! `poll_once` step tests drive), [`answering`] (fair answering of the waiting requests),
//! [`validate`] (checks a deployed model off the serving thread), [`state`] (persists the
//! accepted model durably), [`answer_times`] (the serving thread's answer times) and
//! [`control`] (status, telemetry and deploy endpoints, on their own thread).
//! Errors are [`Error`]; why a model is refused is a [`Refusal`].

#![warn(missing_docs)]

pub mod admission;
pub mod answer_times;
pub mod answering;
pub mod cli;
pub mod control;
mod daemon;
mod error;
pub mod fair_queue;
pub mod realtime;
pub mod serving;
pub mod state;
pub mod systemd;
pub mod termination;
pub mod validate;

pub use daemon::{Service, ServiceOptions};
pub use error::{Error, Refusal};

use std::sync::atomic::AtomicU64;

/// Counters shared by the serving and control threads (relaxed atomics: no lock on the hot path).
#[derive(Debug, Default)]
pub struct Counters {
    /// Compensation requests answered.
    pub requests: AtomicU64,
    /// Points answered.
    pub points: AtomicU64,
    /// Requests refused or failed.
    pub errors: AtomicU64,
    /// Requests answered `Overloaded`.
    pub overloaded: AtomicU64,
    /// Accepted models that could not be persisted.
    pub persist_failures: AtomicU64,
    /// Generation of the model serving (0: none).
    pub generation: AtomicU64,
    /// How long answers took, against the deadline.
    pub answer_times: answer_times::AnswerTimes,
}

/// A model, in its serving form, with the generation it serves as.
#[derive(Debug)]
pub struct Generation {
    /// The model's serving form (built when the model is accepted, off the serving thread).
    pub model: hexacomp_core::fused::FusedModel,
    /// Its generation number (1, 2, …).
    pub number: u64,
}

impl Generation {
    /// `model` serving as generation `number`.
    pub fn new(model: &hexacomp_core::model::Model, number: u64) -> Self {
        Self {
            model: hexacomp_core::fused::FusedModel::new(model),
            number,
        }
    }
}

//! # hexacomp-service (library)
//!
//! The compensation daemon's parts: [`serving`] (the hot path: one function that answers a
//! request into a loaned response, allocation-free, and the serving loop), [`validate`] (checks a
//! deployed model off the serving thread), [`state`] (persists the accepted model atomically) and
//! [`control`] (status and deploy endpoints, on their own thread).

#![warn(missing_docs)]

pub mod admission;
pub mod answering;
pub mod cli;
pub mod control;
pub mod fair_queue;
pub mod realtime;
pub mod serving;
pub mod state;
pub mod validate;

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
}

/// A model with the generation it serves as.
#[derive(Debug)]
pub struct Generation {
    /// The model.
    pub model: hexacomp_core::model::Model,
    /// Its generation number (1, 2, …).
    pub number: u64,
}

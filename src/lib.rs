//! kodama-dag's engine: graph files, the content-addressed cache, the scheduler, run records, and
//! the CLI commands built on them. The stages themselves live in the `kodama-nodes` crate.
//!
//! **Invariant:** the engine knows nothing about geometry or radio. It sees node kinds through
//! the registry (names, typed inputs, an output type, params it can parse, hash and run) and
//! artifacts as opaque values it can serialize.
#![deny(missing_docs)]

pub mod cache;
pub mod cli;
pub mod diag;
pub mod exec;
pub mod explain;
pub mod graph;
pub mod key;
pub mod progress;
pub mod record;
pub mod registry;
pub mod serve;
pub mod slurm;
pub mod sweep;
pub mod syntax;
pub mod watch;

//! End-to-end tests of the `symframe-lab` binary: every experiment at reduced size writes its
//! report, plots and figures; the benchmarks write their figures and a consistent cost model.

mod bench;
mod common;
mod experiment;

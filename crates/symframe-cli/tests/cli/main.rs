//! End-to-end tests of the `symframe` binary: real files in, maps and pictures out, bad input
//! refused with a one-line error naming the file.

mod baselines;
mod calibrate;
mod common;
mod estimate;
mod eval;
mod export;
mod fit;
mod forged;
mod gamma;
mod hostile_folders;
mod hostile_inputs;
mod hostile_jobs;
mod integrate;
mod normal_png;
mod outdir;
mod pictures;
mod reliability;
mod synth;
mod tiles;
mod view;

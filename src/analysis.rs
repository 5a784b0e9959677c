//! Analysis of runs

//! # activesense (the command)
//!
//! Every `activesense` command's options and body, one module each under [`commands`]; the
//! binary (`src/main.rs`) is the clap tree only. The commands a surveyor runs (`episode`,
//! `station`, `geocom-sim`, `sim`, `serial`, `policy upload/info`, `plan`) drive
//! `activesense-instrument`; the lab's (`train`, `eval`, `calibrate`, `bench-*`,
//! `answer-coverage`, `inspect`, `policy quantize/agreement`, `mcu-bench`, `dataset`) drive
//! `activesense-lab`.
//!
//! | module | what it holds |
//! |---|---|
//! | [`commands`] | one module per command, and [`commands::options`] the options they share, declared once |

pub mod commands;

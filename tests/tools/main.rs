//! The binary and the repository as a whole: the real `inbetween` binary run
//! as users run it (`cli`, `import_cli`), and the repository's shape and
//! documents (`tidy`).

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod import_cli;
mod seam;
mod tidy;

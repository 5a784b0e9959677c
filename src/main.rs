//! The `sandstep` command line (`src/cli/`).

fn main() -> std::process::ExitCode {
    sandstep::cli::main()
}

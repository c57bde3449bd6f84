//! The `kodama-dag` binary: the command line of [`kodama_dag::cli`].

fn main() -> std::process::ExitCode {
    std::process::ExitCode::from(kodama_dag::cli::main(std::env::args_os()))
}

//! `vigp`: fit, score, predict and export learned models of the paper's
//! four systems (pendulum, cartpole, double pendulum, fourbar). See
//! `vigp --help` and the `vigp::cli` docs; your own mechanism gets the same
//! tool from `vigp::cli::main::<MyMechanism>()`.

fn main() -> std::process::ExitCode {
    vigp::cli::main_with(&vigp::cli::paper_systems())
}

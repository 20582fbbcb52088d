//! `vigp`: fit, score, predict and export learned models of the paper's
//! four systems (pendulum, cartpole, double pendulum, fourbar) and of the
//! 3-D examples of `vigp::systems::spatial` (furuta, spherical pendulum,
//! 3-D double pendulum, spatial slider-crank, tumbler; in their minimal
//! coordinates). See `vigp --help` and the `vigp::cli` docs; your own
//! mechanism gets the same tool from `vigp::cli::main::<MyMechanism>()`.

fn main() -> std::process::ExitCode {
    let mut systems = vigp::cli::paper_systems();
    systems.extend(vigp::cli::spatial_systems());
    vigp::cli::main_with(&systems)
}

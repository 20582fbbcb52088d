// An input vector whose length is not the mechanism's number of inputs
// (here 1 actuated joint, so 1 or 0) is refused at the call that passes it.
use vigp::__private::nalgebra::SVector;
use vigp::State;
use vigp::embedded::Stepper;

vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { actuated },
        }
    }
}

fn main() {
    let stepper = Stepper::new(Pendulum::default(), 0.01).unwrap();
    let z = State::new([0.1], [0.0]);
    let _ = stepper.step_forced(&z, &SVector::<f64, 1>::zeros());
    let _ = stepper.step_forced(&z, &SVector::<f64, 0>::zeros());
    let _ = stepper.step_forced(&z, &SVector::<f64, 3>::zeros());
}

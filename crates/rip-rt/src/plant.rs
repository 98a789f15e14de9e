//! The emulator's physics: rip-core's nonlinear Furuta pendulum, integrated with RK4.

use rip_core::plant::{FurutaParams, Plant, State};

/// Which physical parameter set the emulator simulates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Model {
    /// Parameters fitted to the paper's linear model (the controllers' design model).
    #[default]
    Paper,
    /// The Quanser QUBE-Servo 2 published parameters (a model mismatch for the paper's gains).
    QubeServo2,
    /// The parameters of a configuration file's `[plant]` section.
    Params(FurutaParams),
}

/// A simulated pendulum: the nonlinear plant and its state.
#[derive(Debug, Clone)]
pub struct PlantSim {
    plant: Plant,
    x: State,
    // The longest RK4 step the plant's fastest mode allows (stiff Coulomb friction).
    max_substep: f64,
}

impl PlantSim {
    /// The `model` plant at rest at arm angle `theta` and pendulum angle `alpha` (0 = upright).
    pub fn new(model: Model, theta: f64, alpha: f64) -> Self {
        let plant = match model {
            Model::Paper => Plant::paper(),
            Model::QubeServo2 => Plant::qube_servo2(),
            // Checked when the file was read (rip_core::spec).
            Model::Params(p) => Plant::new(p).expect("validated [plant] parameters"),
        };
        Self {
            max_substep: plant.max_rk4_substep(),
            plant,
            x: State::new(theta, 0.0, alpha, 0.0),
        }
    }

    /// Advances by `dt` seconds with the motor voltage `u` held: one RK4 step, or as many as
    /// the plant's stability limit needs (a stiff Coulomb friction).
    pub fn step(&mut self, u: f64, dt: f64) {
        let substeps = (dt / self.max_substep).ceil().clamp(1.0, 1000.0) as usize;
        self.plant.advance(&mut self.x, u, 0.0, dt, substeps);
    }

    /// Motor current (A) at the current state with `u` across the windings:
    /// `i = (z(u) − km θ̇) / rm`, `z` the dead zone.
    pub fn motor_current(&self, u: f64) -> f64 {
        self.plant.motor_torque(&self.x, u) / self.plant.params().kt
    }

    /// `[θ, θ̇, α, α̇]`.
    pub fn state(&self) -> [f64; 4] {
        [self.x[0], self.x[1], self.x[2], self.x[3]]
    }
}

//! The emulator's physics: rip-core's nonlinear Furuta pendulum, integrated with RK4, with
//! the motor's windings driven, shorted or open ([`Windings`]).
//!
//! rip-core's plant has the motor torque `τ = k_t (z(u) − k_m θ̇) / R_m` of a motor whose
//! windings see the voltage `u`: driven, or shorted (`u = 0`, back-EMF braking). Open windings
//! carry no current and give no torque; the simulation cancels the back-EMF term with the
//! external torque `τ_d = k_t k_m θ̇ / R_m`, evaluated at every RK4 stage so that the motor
//! torque is exactly zero along the step.

use rip_core::plant::{FurutaParams, Plant, State};

/// What the bridge connects to the motor's windings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Windings {
    /// This voltage across them (V, the plant's sign convention).
    Driven(f64),
    /// Shorted: back-EMF brakes the arm (the same as driving 0 V).
    Shorted,
    /// Open: no current, no torque; the arm coasts.
    Open,
}

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
    /// The same with the arm's stiction: breakaway torque (N·m) above its Coulomb level
    /// (`plant.arm_breakaway`, rip-core's [`Plant::with_arm_breakaway`]).
    Stiction(FurutaParams, f64),
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
            Model::Stiction(p, cs) => Plant::new(p)
                .and_then(|plant| plant.with_arm_breakaway(cs))
                .expect("validated [plant] parameters and arm_breakaway"),
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
        self.step_windings(Windings::Driven(u), dt);
    }

    /// [`step`](Self::step) with the windings driven, shorted or open (module docs).
    pub fn step_windings(&mut self, w: Windings, dt: f64) {
        let substeps = (dt / self.max_substep).ceil().clamp(1.0, 1000.0) as usize;
        match w {
            Windings::Driven(u) => self.plant.advance(&mut self.x, u, 0.0, dt, substeps),
            Windings::Shorted => self.plant.advance(&mut self.x, 0.0, 0.0, dt, substeps),
            Windings::Open => {
                let p = self.plant.params();
                let emf = p.kt * p.km / p.rm;
                let f = |x: &State| self.plant.derivative(x, 0.0, emf * x[1]);
                let h = dt / substeps as f64;
                for _ in 0..substeps {
                    let x = self.x;
                    let k1 = f(&x);
                    let k2 = f(&(x + k1 * (0.5 * h)));
                    let k3 = f(&(x + k2 * (0.5 * h)));
                    let k4 = f(&(x + k3 * h));
                    self.x += (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0);
                }
            }
        }
    }

    /// Motor current (A) at the current state: `i = (z(u) − k_m θ̇) / R_m` (`z` the dead zone)
    /// driven, `−k_m θ̇ / R_m` shorted, 0 open.
    pub fn motor_current(&self, w: Windings) -> f64 {
        let u = match w {
            Windings::Driven(u) => u,
            Windings::Shorted => 0.0,
            Windings::Open => return 0.0,
        };
        self.plant.motor_torque(&self.x, u) / self.plant.params().kt
    }

    /// Puts the plant in state `[θ, θ̇, α, α̇]`.
    pub fn set_state(&mut self, x: [f64; 4]) {
        self.x = State::new(x[0], x[1], x[2], x[3]);
    }

    /// `[θ, θ̇, α, α̇]`.
    pub fn state(&self) -> [f64; 4] {
        [self.x[0], self.x[1], self.x[2], self.x[3]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The emulator's stiction is rip-core's: the same plant, step for step, and not the
    /// plant without it.
    #[test]
    fn the_emulator_sticks_as_the_simulated_plant_does() {
        let p = FurutaParams {
            cr: 0.003,
            vd: 0.4,
            ..FurutaParams::qube_servo2()
        };
        let reference = Plant::new(p).unwrap().with_arm_breakaway(0.006).unwrap();
        let mut sim = PlantSim::new(Model::Stiction(p, 0.006), 0.0, 0.2);
        let mut free = PlantSim::new(Model::Params(p), 0.0, 0.2);
        let mut x = State::new(0.0, 0.0, 0.2, 0.0);
        let substeps = (0.01 / sim.max_substep).ceil().clamp(1.0, 1000.0) as usize;
        for k in 0..200 {
            // A voltage that breaks the arm loose now and then.
            let u = 1.5 * (f64::from(k) * 0.07).sin();
            sim.step(u, 0.01);
            free.step(u, 0.01);
            reference.advance(&mut x, u, 0.0, 0.01, substeps);
            assert_eq!(sim.state(), [x[0], x[1], x[2], x[3]], "step {k}");
        }
        assert!((free.state()[0] - sim.state()[0]).abs() > 1e-4);
    }

    /// Energy balance, `E(T) − E(0) = −∫ c θ̇² dt` on a plant without pendulum damping, with
    /// `c = d_r` when the windings are open and `d_r + k_t k_m / R_m` when shorted (no source
    /// of energy in either), `E` rip-core's energy function; and the current each reports.
    #[test]
    fn open_windings_coast_and_shorted_windings_brake_by_their_dissipation() {
        let p = FurutaParams {
            dp: 0.0,
            ..FurutaParams::qube_servo2()
        };
        let plant = Plant::new(p).unwrap();
        let energy = |x: [f64; 4]| plant.energy(&State::new(x[0], x[1], x[2], x[3]));
        for (w, c) in [
            (Windings::Open, p.dr),
            (Windings::Shorted, p.dr + p.kt * p.km / p.rm),
        ] {
            let mut sim = PlantSim::new(Model::Params(p), 0.0, 2.5);
            sim.set_state([0.0, 10.0, 2.5, 3.0]);
            let e0 = energy(sim.state());
            let mut lost = 0.0;
            let h = 1e-4;
            for _ in 0..5000 {
                let before = sim.state()[1];
                sim.step_windings(w, h);
                let after = sim.state()[1];
                lost += 0.5 * h * c * (before * before + after * after);
            }
            let e1 = energy(sim.state());
            assert!(
                ((e0 - e1) - lost).abs() < 1e-4 * lost,
                "{w:?}: lost {} J, dissipated {lost} J",
                e0 - e1
            );
            let rate = sim.state()[1];
            let current = sim.motor_current(w);
            let want = if w == Windings::Open {
                0.0
            } else {
                -p.km * rate / p.rm
            };
            assert!((current - want).abs() < 1e-12, "{w:?}: {current} vs {want}");
        }
        // Shorted is driving 0 V.
        let mut a = PlantSim::new(Model::Paper, 0.0, 0.3);
        let mut b = a.clone();
        a.set_state([0.0, 5.0, 0.3, -1.0]);
        b.set_state([0.0, 5.0, 0.3, -1.0]);
        a.step_windings(Windings::Shorted, 0.01);
        b.step(0.0, 0.01);
        assert_eq!(a.state(), b.state());
    }
}

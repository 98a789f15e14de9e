//! The onboard MPC's iteration bound as part of the design: the host caps the uploaded
//! design's `max_iterations` to what fits half the period on the STM32F407 and refuses one
//! that does not fit, and so does the device's law when it loads the image. The reference is the firmware's QEMU measurement of the paper's MPC
//! (firmware/README.md): a worst step of 17 800 + 5 300 (I − 1) instructions, 28 339 measured
//! at its 3 iterations, against 168 MHz / CPI 2 / half the period.

use rip_device::law::ControlLaw;
use rip_device::Onboard;
use rip_rt::config::Config;
use rip_rt::controllers::ControllerKind;
use rip_rt::onboard;

/// The largest I whose measured worst step fits half of `period_us` at 168 MHz and CPI 2.
fn measured_cap(period_us: u64) -> u32 {
    let budget = period_us * 168 / 2 / 2;
    (1..=1000u32)
        .take_while(|&i| 17_800 + 5_300 * u64::from(i - 1) <= budget)
        .last()
        .unwrap_or(0)
}

fn cfg_at(period_ms: f64) -> Config {
    let mut cfg = Config::default();
    cfg.loop_.period_ms = period_ms;
    cfg
}

fn loads(image: &[u8]) -> bool {
    let mut law = Box::new(ControlLaw::<f64, { onboard::MAX_IMAGE }>::new());
    law.buffer()[..image.len()].copy_from_slice(image);
    law.load(image.len()).is_ok()
}

#[test]
fn the_uploaded_mpc_carries_the_iteration_cap_that_fits_its_period() {
    for (period_ms, period_us) in [(1.0, 1_000), (10.0, 10_000)] {
        let cfg = cfg_at(period_ms);
        let d = onboard::design(ControllerKind::Mpc, &cfg).unwrap();
        assert_eq!(d.max_iterations, measured_cap(period_us), "{period_ms} ms");
        assert!(loads(&onboard::image(&d, &cfg).unwrap()), "{period_ms} ms");
    }
    // The measurement's own figures: I ≤ 5 at 1 kHz, I ≤ 76 at 100 Hz.
    assert_eq!((measured_cap(1_000), measured_cap(10_000)), (5, 76));
}

#[test]
fn the_step_model_bounds_the_worst_step_measured_in_qemu() {
    let d = onboard::design(ControllerKind::Mpc, &cfg_at(10.0)).unwrap();
    assert_eq!((d.nx, d.ncon, d.nz()), (5, 107, 4), "the measured design");
    assert!(d.worst_step_instructions_at(3) >= 28_339);
    for i in 1..=10 {
        let model = d.worst_step_instructions_at(i);
        let measured = 17_800 + 5_300 * u64::from(i - 1);
        // Above the measurement, by at most 10 %.
        assert!(
            model >= measured && model * 10 <= measured * 11,
            "I = {i}: {model}"
        );
    }
}

#[test]
fn a_design_whose_iteration_bound_cannot_fit_its_period_is_refused() {
    let cfg = cfg_at(1.0);
    let mut d = onboard::design(ControllerKind::Mpc, &cfg).unwrap();
    d.max_iterations = measured_cap(1_000) + 1;
    let err = d.check_step_budget().unwrap_err().to_string();
    assert!(err.contains("max_iterations"), "{err}");
    // The device's own check: its law refuses the image at the commit.
    assert!(!loads(&onboard::image(&d, &cfg).unwrap()));
    // The configured default, 200, as it would have been sent uncapped.
    d.max_iterations = 200;
    assert!(d.check_step_budget().is_err());
    assert!(!loads(&onboard::image(&d, &cfg).unwrap()));
    d.max_iterations = measured_cap(1_000);
    assert!(d.check_step_budget().is_ok());
    assert!(loads(&onboard::image(&d, &cfg).unwrap()));
}

/// The 1 kHz MPC of the processor-in-the-loop check: the estimator and the move at 1 ms, the
/// prediction on the paper's 10 ms grid (`mpc.prediction_step = 10`, P = 50: 0.5 s).
#[test]
fn the_1khz_mpc_on_a_10ms_grid_is_the_papers_qp_and_fits_half_its_period() {
    let mut fast = cfg_at(1.0);
    fast.spec.mpc.prediction_step = 10;
    let d = onboard::design(ControllerKind::Mpc, &fast).unwrap();
    let paper = onboard::design(ControllerKind::Mpc, &cfg_at(10.0)).unwrap();
    assert_eq!(d.ts, 1e-3);
    // Ten 1 ms zero-order-hold steps are one 10 ms step of the same continuous plant, so the
    // condensed QP is the one of the 100 Hz design, discretised on its own.
    let (nz, ncon, n) = (d.nz(), d.ncon, d.nx);
    assert_eq!((d.horizon, n, ncon, nz), (50, 5, 107, 4));
    let close = |name: &str, a: &[f64], b: &[f64]| {
        let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let err = a
            .iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(err <= 1e-9 * scale, "{name}: {err} of {scale}");
    };
    close("h", &d.h[..nz * nz], &paper.h[..nz * nz]);
    close("fx", &d.fx[..nz * n], &paper.fx[..nz * n]);
    close("fu", &d.fu[..nz], &paper.fu[..nz]);
    close("fr", &d.fr[..nz * 2], &paper.fr[..nz * 2]);
    close("ac", &d.ac[..ncon * nz], &paper.ac[..ncon * nz]);
    close("b0", &d.b0[..ncon], &paper.b0[..ncon]);
    close("bx", &d.bx[..ncon * n], &paper.bx[..ncon * n]);
    close("bu", &d.bu[..ncon], &paper.bu[..ncon]);
    // The estimator is not the 100 Hz one: its model is the 1 ms step.
    assert!((d.a[1] - paper.a[1]).abs() > 1e-3);
    // The same QP, so the same cap as the P = 50 design at 1 ms: 5 iterations, whose modelled
    // worst step fits 42 000 instructions.
    assert_eq!(d.max_iterations, measured_cap(1_000));
    assert!(d.worst_step_instructions() <= 42_000);
    assert!(loads(&onboard::image(&d, &fast).unwrap()));
}

/// Telemetry's fallback count is the law's: an MPC held to one QP iteration cannot finish the
/// active-set solve of a state that saturates the input, and applies its fallback law on each
/// such step; with the cap that fits its period the same run falls back on none. The count
/// starts again at the onboard start (the law's reset).
#[test]
fn the_law_counts_the_steps_that_applied_the_mpcs_fallback() {
    let cfg = cfg_at(10.0);
    let mut d = onboard::design(ControllerKind::Mpc, &cfg).unwrap();
    let capped = d.max_iterations;
    let run = |max_iterations: u32, d: &mut rip_control::Design| {
        d.max_iterations = max_iterations;
        let image = onboard::image(d, &cfg).unwrap();
        let mut law = Box::new(ControlLaw::<f64, { onboard::MAX_IMAGE }>::new());
        law.buffer()[..image.len()].copy_from_slice(&image);
        law.load(image.len()).unwrap();
        let sensor = *law.sensor();
        // The pendulum's upright count, from the sensor's own conversion.
        let upright = (sensor.pendulum_offset / sensor.pendulum_rad_per_count).round() as i32;
        assert!(sensor.angles([0, upright])[1].abs() < sensor.pendulum_rad_per_count);
        law.reset([0, upright]);
        // 0.3 rad off upright and back: the move saturates for several steps.
        let tilt = (0.3 / sensor.pendulum_rad_per_count).round() as i32;
        let mut saturated = 0;
        for k in 0..60 {
            let offset = if k < 20 { tilt } else { 0 };
            let u = law.step([0, upright + offset]);
            saturated += usize::from(u.abs() >= d.input_bounds[1] - 1e-6);
        }
        let stats = law.controller().unwrap().stats();
        let counted = law.fallbacks();
        assert_eq!(
            counted,
            stats.iteration_limits + stats.solver_failures,
            "the law reports its controller's count"
        );
        law.reset([0, upright]);
        assert_eq!(law.fallbacks(), 0, "reset at the onboard start");
        (counted, saturated)
    };
    let (one, saturated) = run(1, &mut d);
    eprintln!("one iteration: {one} fallbacks in 60 steps, {saturated} of them saturated");
    assert!(saturated > 0, "the tilt never saturated the input");
    assert!(one > 0, "one iteration sufficed on every step");
    let (at_cap, _) = run(capped, &mut d);
    assert_eq!(at_cap, 0, "{capped} iterations fell back");
}

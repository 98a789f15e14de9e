//! The environments against the single environment, `Plant::advance`, the sensor model and
//! their stated draws.

use super::*;
use crate::plant::{Plant, State};
use crate::sim::SensorModel;
use crate::spec::Param;

fn run(config: &EnvConfig, n: usize, seeds: &[u64], steps: usize) -> Vec<f32> {
    let mut env = VecEnv::new(config.clone(), n).unwrap();
    let mut obs = vec![0.0f32; n * OBS_DIM];
    env.reset(seeds, &[], &mut obs).unwrap();
    let mut all = obs.clone();
    let (mut r, mut te, mut tr) = (vec![0.0; n], vec![false; n], vec![false; n]);
    for k in 0..steps {
        // Each environment's actions depend on its seed, not on its place in the vector.
        let a: Vec<f32> = seeds
            .iter()
            .map(|s| ((k as u64 * 7 + s * 3) % 11) as f32 / 5.0 - 1.0)
            .collect();
        env.step(&a, true, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap();
        all.extend_from_slice(&obs);
        all.extend(r.iter().map(|v| *v as f32));
    }
    all
}

fn randomised() -> EnvConfig {
    EnvConfig {
        task: Task::SwingUp,
        max_steps: 50,
        observation_latency: 2,
        randomisation: Randomisation {
            relative: vec![(Param::Mp, 0.2), (Param::Rm, 0.2)],
            dead_zone: Some([0.0, 0.5]),
            arm_friction: Some([0.0, 0.003]),
            pendulum_friction: Some([0.0, 2e-5]),
            action_delay: Some([0, 3]),
            noise_std: Some([0.0, 2e-3]),
            covariance: Some(ParamCovariance {
                params: vec![Param::Dr, Param::Dp],
                matrix: vec![1e-8, 0.0, 0.0, 1e-10],
            }),
        },
        ..Default::default()
    }
}

#[test]
fn each_environment_of_a_vector_is_the_single_environment_of_its_seed() {
    let config = randomised();
    let seeds = [11u64, 5, 99, 3, 42];
    let together = run(&config, seeds.len(), &seeds, 130);
    let per_step = seeds.len() * (OBS_DIM + 1);
    for (i, &s) in seeds.iter().enumerate() {
        let alone = run(&config, 1, &[s], 130);
        for k in 0..130 {
            let base = seeds.len() * OBS_DIM + k * per_step;
            let o = &together[base + i * OBS_DIM..base + (i + 1) * OBS_DIM];
            let a = &alone[OBS_DIM + k * (OBS_DIM + 1)..OBS_DIM + k * (OBS_DIM + 1) + OBS_DIM];
            assert_eq!(o, a, "env {i} step {k}");
        }
    }
}

#[test]
fn the_lanes_integrate_each_environment_with_the_bits_of_plant_advance() {
    // Randomised plants (different coefficients in every lane, dead zone, Coulomb friction
    // in some), 7 environments (a partial chunk of lanes), short episodes so that lanes
    // reset while their neighbours step: every true state is Plant::advance's, to the bit.
    let config = EnvConfig {
        max_steps: 9,
        ..randomised()
    };
    let n = 2 * LANES - 1;
    let mut env = VecEnv::new(config.clone(), n).unwrap();
    let mut obs = vec![0.0f32; n * OBS_DIM];
    let seeds: Vec<u64> = (0..n as u64).map(|s| 1000 + s).collect();
    env.reset(&seeds, &[], &mut obs).unwrap();
    let (mut r, mut te, mut tr) = (vec![0.0; n], vec![false; n], vec![false; n]);
    let mut inputs: Vec<Vec<f64>> = vec![Vec::new(); n];
    let mut checked = 0;
    for k in 0..40 {
        let a: Vec<f32> = (0..n)
            .map(|i| ((k * 5 + i * 3) % 9) as f32 / 4.0 - 1.0)
            .collect();
        let before: Vec<(State, bool)> = (0..n)
            .map(|i| (State::from(env.env(i).state()), env.env(i).done))
            .collect();
        env.step(&a, true, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap();
        for i in 0..n {
            let e = env.env(i);
            let (x0, was_done) = before[i];
            if was_done {
                inputs[i].clear();
                continue;
            }
            inputs[i].push(config.u_limit * f64::from(a[i]).clamp(-1.0, 1.0));
            let u = inputs[i][inputs[i].len() - 1 - e.action_delay().min(inputs[i].len() - 1)];
            let u = if e.action_delay() >= inputs[i].len() {
                0.0
            } else {
                u
            };
            let mut x = x0;
            e.plant()
                .advance(&mut x, u, 0.0, config.ts, config.substeps);
            let want: [f64; 4] = x.into();
            assert_eq!(
                e.state().map(f64::to_bits),
                want.map(f64::to_bits),
                "env {i} step {k}"
            );
            checked += 1;
        }
    }
    assert!(checked > 200, "{checked}");
    assert!(env.envs.iter().any(|e| e.plant().params().cr > 0.0));
}

#[test]
fn parallel_and_serial_steps_agree_bit_for_bit() {
    let config = randomised();
    let n = PARALLEL_MIN_ENVS + 3;
    let seeds: Vec<u64> = (0..n as u64).collect();
    let big = run(&config, n, &seeds, 20);
    let first = run(&config, 3, &seeds[..3], 20);
    for k in 0..20 {
        let b = n * OBS_DIM + k * n * (OBS_DIM + 1);
        let f = 3 * OBS_DIM + k * 3 * (OBS_DIM + 1);
        assert_eq!(&big[b..b + 3 * OBS_DIM], &first[f..f + 3 * OBS_DIM]);
    }
}

#[test]
fn the_plant_step_is_rip_cores_rk4_and_the_observation_its_sensor() {
    // No noise, no quantisation: the observation is cos/sin of the true state that
    // Plant::advance gives, and the rates the documented filter of the true angles.
    let config = EnvConfig {
        sensor: SensorModel::default(),
        init_spread: 0.0,
        ..Default::default()
    };
    let mut env = VecEnv::new(config.clone(), 1).unwrap();
    let mut obs = vec![0.0f32; OBS_DIM];
    env.reset(&[0], &[], &mut obs).unwrap();
    let plant = Plant::new(config.params).unwrap();
    let mut x = State::new(0.0, 0.0, 0.0, 0.0);
    let a_f = (-2.0 * std::f64::consts::PI * 20.0 * 0.01f64).exp();
    let mut rates = [0.0; 2];
    let mut prev = [0.0; 2];
    let (mut r, mut te, mut tr) = ([0.0], [false], [false]);
    for k in 0..30 {
        let a = if k % 2 == 0 { 0.3f32 } else { -0.2 };
        env.step(&[a], false, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap();
        plant.advance(&mut x, 12.0 * f64::from(a), 0.0, 0.01, 10);
        for i in 0..2 {
            rates[i] = a_f * rates[i] + (1.0 - a_f) * (x[2 * i] - prev[i]) / 0.01;
            prev[i] = x[2 * i];
        }
        let expected = [
            x[0].cos(),
            x[0].sin(),
            x[2].cos(),
            x[2].sin(),
            rates[0],
            rates[1],
        ];
        for (o, e) in obs.iter().zip(expected) {
            assert!(
                (f64::from(*o) - e).abs() < 1e-6 * (1.0 + e.abs()),
                "{o} vs {e}"
            );
        }
        let want = 1.0
            - (0.8 * x[2].abs() + 0.2 * x[0].abs()) / std::f64::consts::PI
            - 0.01 * f64::from(a).powi(2);
        assert!((r[0] - want).abs() < 1e-12);
    }
}

#[test]
fn action_delay_and_latency_shift_by_whole_periods() {
    let base = EnvConfig {
        sensor: SensorModel::default(),
        init_spread: 0.0,
        ..Default::default()
    };
    let trace = |c: &EnvConfig, actions: &[f32]| {
        let mut env = VecEnv::new(c.clone(), 1).unwrap();
        let mut obs = vec![0.0f32; OBS_DIM];
        env.reset(&[1], &[], &mut obs).unwrap();
        let mut out = vec![obs.clone()];
        let (mut r, mut te, mut tr) = ([0.0], [false], [false]);
        for a in actions {
            env.step(&[*a], false, &mut obs, &mut r, &mut te, &mut tr)
                .unwrap();
            out.push(obs.clone());
        }
        out
    };
    let pulse: Vec<f32> = (0..20).map(|k| if k == 0 { 0.5 } else { 0.0 }).collect();
    let delayed = EnvConfig {
        action_delay: 3,
        ..base.clone()
    };
    let mut shifted = vec![0.0f32; 3];
    shifted.extend_from_slice(&pulse[..17]);
    assert_eq!(trace(&delayed, &pulse), trace(&base, &shifted));
    let late = EnvConfig {
        observation_latency: 2,
        ..base.clone()
    };
    let now = trace(&base, &pulse);
    let seen = trace(&late, &pulse);
    for k in 2..seen.len() {
        assert_eq!(seen[k], now[k - 2]);
    }
}

#[test]
fn autoreset_resets_on_the_step_after_the_end() {
    let config = EnvConfig {
        max_steps: 3,
        ..Default::default()
    };
    let mut env = VecEnv::new(config, 2).unwrap();
    let mut obs = vec![0.0f32; 2 * OBS_DIM];
    env.reset(&[1, 2], &[], &mut obs).unwrap();
    let (mut r, mut te, mut tr) = ([0.0; 2], [false; 2], [false; 2]);
    for _ in 0..3 {
        env.step(&[0.0, 0.0], true, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap();
    }
    assert_eq!(tr, [true, true]);
    env.step(&[1.0, 1.0], true, &mut obs, &mut r, &mut te, &mut tr)
        .unwrap();
    assert_eq!((r, te, tr), ([0.0; 2], [false; 2], [false; 2]));
    assert_eq!(env.env(0).steps, 0);
}

#[test]
fn draws_follow_the_stated_ranges_and_the_covariance() {
    let config = randomised();
    let mut env = VecEnv::new(config.clone(), 1).unwrap();
    let mut obs = vec![0.0f32; OBS_DIM];
    let nominal = config.params;
    let (mut dr, mut dr2) = (0.0, 0.0);
    let n = 4000;
    for s in 0..n {
        env.reset(&[s], &[], &mut obs).unwrap();
        let p = env.env(0).plant().params();
        assert!((p.mp / nominal.mp - 1.0).abs() <= 0.2);
        assert!((0.0..=0.5).contains(&p.vd) && (0.0..=0.003).contains(&p.cr));
        assert!(env.env(0).action_delay() <= 3);
        let d = p.dr - nominal.dr;
        dr += d;
        dr2 += d * d;
    }
    let mean = dr / n as f64;
    let std = (dr2 / n as f64 - mean * mean).sqrt();
    // Σ₀₀ = 1e-8: standard deviation 1e-4, estimated to within a few per cent.
    assert!((std / 1e-4 - 1.0).abs() < 0.05, "std {std}");
    assert!(mean.abs() < 5.0 * 1e-4 / (n as f64).sqrt());
}

#[test]
fn bad_settings_are_named_and_change_nothing() {
    let bad = EnvConfig {
        action_delay: MAX_DELAY + 1,
        ..Default::default()
    };
    assert!(VecEnv::new(bad, 1)
        .unwrap_err()
        .to_string()
        .contains("action_delay"));
    let mut env = VecEnv::new(EnvConfig::default(), 2).unwrap();
    let mut obs = vec![0.0f32; 2 * OBS_DIM];
    env.reset(&[1, 2], &[], &mut obs).unwrap();
    let before = env.env(1).state();
    let (mut r, mut te, mut tr) = ([0.0; 2], [false; 2], [false; 2]);
    let err = env
        .step(&[0.0, f32::NAN], true, &mut obs, &mut r, &mut te, &mut tr)
        .unwrap_err();
    assert!(err.to_string().contains("actions"));
    assert_eq!(env.env(1).state(), before);
}

#[test]
fn replay_fits_the_plants_own_trajectory_and_not_a_wrong_plants() {
    let plant = Plant::qube_servo2();
    let u: Vec<f64> = (0..300).map(|k| 2.0 * (k as f64 * 0.05).sin()).collect();
    let x0 = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let traj = plant.integrate(&x0, &u[..299], 0.01, 10).unwrap();
    let y: Vec<[f64; 2]> = traj.iter().map(|x| [x[0], x[2]]).collect();
    // The start's rate estimate is a forward difference, not the true zero rate: the fit is
    // close but not exact, and a wrong plant fits far worse.
    let fit = replay(&plant, &y, &u, 0.01, 10).unwrap();
    assert!(
        fit.nrmse[0] < 0.05 && fit.nrmse[1] < 0.05,
        "{:?}",
        fit.nrmse
    );
    let mut wrong = *plant.params();
    wrong.kt *= 1.5;
    let worse = replay(&Plant::new(wrong).unwrap(), &y, &u, 0.01, 10).unwrap();
    assert!(
        worse.nrmse[0] > 5.0 * fit.nrmse[0].max(1e-3),
        "{:?}",
        worse.nrmse
    );
}

#[test]
fn observed_rates_are_the_filtered_difference_and_a_bad_sample_spans_two_periods() {
    // The closed form of the module docs, written out: a first-order low-pass of the backward
    // difference, and over a skipped (non-finite) sample the zero-order hold over 2 Ts.
    let (ts, fc) = (0.01, 20.0);
    let a = (-2.0 * std::f64::consts::PI * fc * ts).exp();
    let mut obs = Observer::new(ts, fc);
    let y = [[0.1, -0.2], [0.13, -0.18], [f64::NAN, 0.0], [0.2, -0.1]];
    let o0 = obs.observe(y[0]);
    assert_eq!((o0[4], o0[5]), (0.0, 0.0));
    let o1 = obs.observe(y[1]);
    let r1 = [0, 1].map(|j| (1.0 - a) * (y[1][j] - y[0][j]) / ts);
    assert!((o1[4] - r1[0]).abs() < 1e-12 && (o1[5] - r1[1]).abs() < 1e-12);
    let o2 = obs.observe(y[2]);
    assert_eq!(
        (o2[4], o2[5]),
        (o1[4], o1[5]),
        "a bad sample keeps the rates"
    );
    let o3 = obs.observe(y[3]);
    for j in 0..2 {
        let expected = a * a * r1[j] + (1.0 - a * a) * (y[3][j] - y[1][j]) / (2.0 * ts);
        assert!(
            (o3[4 + j] - expected).abs() < 1e-12,
            "{j}: {} vs {expected}",
            o3[4 + j]
        );
    }
    assert!((o3[0] - 0.2f64.cos()).abs() < 1e-15 && (o3[3] - (-0.1f64).sin()).abs() < 1e-15);
}

/// Steps `env` `steps` times with fixed actions; the observations and rewards, as bits.
fn trace(env: &mut VecEnv, steps: usize) -> Vec<u64> {
    let n = env.len();
    let mut obs = vec![0.0f32; n * OBS_DIM];
    let (mut r, mut te, mut tr) = (vec![0.0; n], vec![false; n], vec![false; n]);
    let mut out = Vec::new();
    for k in 0..steps {
        let a: Vec<f32> = (0..n)
            .map(|i| ((k + 3 * i) % 9) as f32 / 4.0 - 1.0)
            .collect();
        env.step(&a, true, &mut obs, &mut r, &mut te, &mut tr)
            .unwrap();
        out.extend(obs.iter().map(|v| u64::from(v.to_bits())));
        out.extend(r.iter().map(|v| v.to_bits()));
    }
    out
}

#[test]
fn a_restored_environment_continues_with_the_same_bits() {
    let mut env = VecEnv::new(randomised(), 3).unwrap();
    let mut obs = vec![0.0f32; 3 * OBS_DIM];
    env.reset(&[7, 8, 9], &[], &mut obs).unwrap();
    // Mid-episode, with draws taken and delays filled; then through autoresets (max_steps 50),
    // which draw from each generator where the original left it.
    trace(&mut env, 37);
    let mut restored = VecEnv::from_bytes(&env.to_bytes()).unwrap();
    assert_eq!(restored.config(), env.config());
    assert_eq!(trace(&mut restored, 140), trace(&mut env, 140));
}

#[test]
fn bytes_that_are_not_a_saved_environment_are_an_error_naming_state() {
    let mut env = VecEnv::new(randomised(), 2).unwrap();
    let mut obs = vec![0.0f32; 2 * OBS_DIM];
    env.reset(&[1, 2], &[], &mut obs).unwrap();
    let bytes = env.to_bytes();
    let named = |r: crate::error::Result<VecEnv>| matches!(r, Err(crate::error::RipError::InvalidParameter { ref name, .. }) if name == "state");
    // Every truncation, a trailing byte, and every byte flipped to 0xff in turn: an error or
    // a valid environment, never a panic.
    for len in 0..bytes.len() {
        assert!(named(VecEnv::from_bytes(&bytes[..len])), "{len}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(named(VecEnv::from_bytes(&longer)));
    for i in 0..bytes.len() {
        let mut b = bytes.clone();
        b[i] = 0xff;
        let _ = VecEnv::from_bytes(&b);
    }
}

#[test]
fn seeds_from_one_seed_never_wrap() {
    let env = VecEnv::new(EnvConfig::default(), 3).unwrap();
    assert_eq!(env.seeds_from(5).unwrap(), vec![5, 6, 7]);
    assert_eq!(
        env.seeds_from(u64::MAX - 2).unwrap(),
        vec![u64::MAX - 2, u64::MAX - 1, u64::MAX]
    );
    for base in [u64::MAX - 1, u64::MAX] {
        let err = env.seeds_from(base).unwrap_err();
        assert!(
            matches!(err, crate::error::RipError::InvalidParameter { ref name, .. } if name == "seed")
        );
    }
}

#[test]
fn rig_settings_follow_the_rig_files_ranges() {
    let bad = |c: EnvConfig, name: &str| {
        let err = c.validate().unwrap_err();
        assert!(
            matches!(err, crate::error::RipError::InvalidParameter { name: ref n, .. } if n == name),
            "{err}"
        );
    };
    let counts = |c: f64| EnvConfig {
        sensor: SensorModel {
            counts_per_rev: Some([2048.0, c]),
            ..EnvConfig::default().sensor
        },
        ..Default::default()
    };
    for c in [1.0, 127.0, 2048.5, f64::from(1u32 << 24) + 1.0, f64::NAN] {
        bad(counts(c), "encoder_counts");
    }
    counts(128.0).validate().unwrap();
    for ts in [1e-12, 0.0009, 0.021, f64::INFINITY] {
        bad(
            EnvConfig {
                ts,
                ..Default::default()
            },
            "Ts",
        );
    }
    let mut c = EnvConfig::default();
    c.randomisation.dead_zone = Some([100.0, 200.0]);
    bad(c, "randomize.Vd");
    let mut c = EnvConfig::default();
    c.params.vd = c.u_limit;
    bad(c, "Vd");
}

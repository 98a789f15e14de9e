//! Python bindings of `rip_core::stats`: the Wilson score interval of a Monte Carlo success
//! rate and the success count a controller of a given probability reaches. The public
//! wrappers, with the confidence level rather than the normal quantile, are
//! `riprs.stats`.

use pyo3::prelude::*;

use crate::convert::Count;
use crate::errors::IntoPyResult;

/// Wilson score interval of ``successes`` in ``runs`` at the normal quantile ``z``.
///
/// Parameters
/// ----------
/// successes, runs : int
///     Successes and runs, ``0 <= successes <= runs``, ``runs >= 1``.
/// z : float
///     The normal quantile (1.959964 for a two-sided 95 % interval).
///
/// Returns
/// -------
/// tuple of float
///     ``(low, high)`` within [0, 1].
///
/// Raises
/// ------
/// InvalidParameterError
///     A count out of range, or ``z`` not finite and positive, naming the argument.
#[pyfunction]
fn wilson(successes: Count, runs: Count, z: f64) -> PyResult<(f64, f64)> {
    let k = successes.get("successes")? as u64;
    let n = runs.get("runs")? as u64;
    rip_core::stats::wilson(k, n, z).py()
}

/// The most successes of ``runs`` that a controller succeeding with probability ``p`` in each
/// run reaches with probability at least ``confidence``.
///
/// Parameters
/// ----------
/// runs : int
///     Independent runs, ``>= 0``.
/// p : float
///     Success probability of one run, in [0, 1].
/// confidence : float
///     In (0, 1).
///
/// Returns
/// -------
/// int
///     The largest ``k`` with ``P(Binomial(runs, p) >= k) >= confidence``.
///
/// Raises
/// ------
/// InvalidParameterError
///     ``runs`` negative, ``p`` or ``confidence`` out of range, naming the argument.
#[pyfunction]
fn guaranteed_successes(runs: Count, p: f64, confidence: f64) -> PyResult<u64> {
    let n = runs.get("runs")? as u64;
    rip_core::stats::guaranteed_successes(n, p, confidence).py()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(wilson, m)?)?;
    m.add_function(wrap_pyfunction!(guaranteed_successes, m)?)?;
    Ok(())
}

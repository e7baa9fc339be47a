//! Run statistics written by `--stats out.json`.

use crate::color::Rgb;
use crate::measures::information::InformationMeasures;
use crate::pipeline::{SimulationSettings, Solution};
use serde::Serialize;

/// CPU seconds (user and system, all threads) this process has used so far, from `/proc/self/stat`
/// (in clock ticks of 1/100 s, Linux's fixed `USER_HZ`); 0 where that cannot be read.
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which may hold spaces) in parentheses: utime and stime are the
    // 14th and 15th of the line, the 12th and 13th after it.
    let after_name = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let ticks: f64 = after_name
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|t| t.parse::<f64>().ok())
        .sum();
    ticks / 100.0
}

/// Seconds spent in each phase of a run.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseSeconds {
    pub load: f64,
    pub bvh: f64,
    pub refine: f64,
    pub solve: f64,
    /// The a-posteriori error estimates after the passes.
    pub estimate: f64,
    pub render: f64,
}

/// The statistics of one run, as written to the stats JSON.
#[derive(Clone, Debug, Serialize)]
pub struct RunStats {
    pub scene: String,
    pub polygons: usize,
    pub patches: usize,
    pub elements: usize,
    pub leaf_elements: usize,
    pub links: usize,
    /// All rays cast by the solver: form factors, oracle evaluations and Monte Carlo shooting lines.
    pub rays: u64,
    pub form_factor_rays: u64,
    /// Shaft tests and the coupling rays they saved (`--visibility-reuse shaft`).
    pub shaft_tests: u64,
    pub rays_saved: u64,
    pub oracle_rays: u64,
    pub shooting_rays: u64,
    pub iterations: usize,
    pub passes: usize,
    pub converged: bool,
    pub seconds: PhaseSeconds,
    /// Σ π A E (W per channel).
    pub emitted_power: Rgb,
    /// Σ π A (1 - ρ) H over the leaves of surfaces that reflect (W per channel). Black surfaces
    /// (ρ = 0, a lamp's own face) get no links, so what they absorb is not counted: a closed white box lit
    /// by a two-sided black lamp 1 mm under its ceiling shows 75% of the emission absorbed at
    /// ρ = 0.5, 39% at ρ = 0.98 (the lamp's back lights the gap, and the lamp takes what returns).
    pub absorbed_power: Rgb,
    pub threads: usize,
    /// Bytes held by elements, coefficients and links.
    pub memory_bytes: usize,
    /// Relative change of total power after each sweep.
    pub residuals: Vec<f64>,
    /// The a-posteriori error estimate (Bekaert–Willems §4) over the leaves, and error control's end.
    pub error: crate::solvers::ErrorReport,
    /// Splits refused for the element budget (`--max-elements`, `--max-memory`).
    pub refused_by_budget: usize,
    /// Progressive multi-gridding's steps (`--link-budget`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub steps: Vec<crate::solvers::multigrid::StepReport>,
    pub settings: SimulationSettings,
    /// Information-theoretic measures (`radiosity measure`), Feixas et al. eqs. (3), (10).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub information: Option<InformationMeasures>,
}

impl RunStats {
    pub fn new(
        scene: &str,
        polygons: usize,
        solution: &Solution,
        settings: &SimulationSettings,
    ) -> Self {
        let h = &solution.hierarchy;
        let r = &solution.report;
        RunStats {
            scene: scene.to_string(),
            polygons,
            patches: h.patches.len(),
            elements: h.elements.len(),
            leaf_elements: h.leaf_count(),
            links: h.link_count(),
            rays: r.form_factor_rays + r.oracle_rays + r.shooting_rays,
            form_factor_rays: r.form_factor_rays,
            shaft_tests: r.shaft_tests,
            rays_saved: r.rays_saved,
            oracle_rays: r.oracle_rays,
            shooting_rays: r.shooting_rays,
            iterations: r.iterations,
            passes: r.passes,
            converged: r.converged,
            seconds: PhaseSeconds {
                bvh: solution.visibility_seconds,
                refine: r.refine_seconds,
                solve: r.solve_seconds,
                estimate: r.estimate_seconds,
                ..Default::default()
            },
            emitted_power: r.emitted_power,
            absorbed_power: r.absorbed_power,
            threads: rayon::current_num_threads(),
            memory_bytes: h.memory_bytes(),
            residuals: r.residuals.clone(),
            error: r.error.clone(),
            refused_by_budget: r.refused_by_budget,
            steps: r.steps.clone(),
            settings: settings.clone(),
            information: None,
        }
    }

    /// The statistics without timings and thread count: what must be identical for any thread count.
    pub fn deterministic_part(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).expect("stats serialise");
        if let Some(map) = v.as_object_mut() {
            map.remove("seconds");
            map.remove("threads");
        }
        remove_from_each(v.get_mut("steps"), &["seconds", "cpu_seconds"]);
        remove_from_each(
            v.get_mut("error").and_then(|e| e.get_mut("passes")),
            &["refine_seconds", "solve_seconds", "estimate_seconds"],
        );
        v
    }
}

/// Removes `keys` from every object of the array `list` (if it is one).
fn remove_from_each(list: Option<&mut serde_json::Value>, keys: &[&str]) {
    for entry in list.and_then(|l| l.as_array_mut()).into_iter().flatten() {
        if let Some(entry) = entry.as_object_mut() {
            for key in keys {
                entry.remove(*key);
            }
        }
    }
}

use radiosity::color::Rgb;
use radiosity::geometry::DVec3;
use radiosity::pipeline::{simulate, SimulationSettings, SolverKind};
use radiosity::progress::Progress;
use radiosity::scene::generators;
fn main() {
    let scene = generators::lit_box(DVec3::new(2.0, 1.0, 1.5), Rgb::new(0.7, 0.5, 0.3), 10.0);
    for (eps, min_area) in [(1e-3, 1e-5), (3e-4, 1e-5), (1e-4, 1e-5), (1e-5, 1e-4), (1e-6, 1e-3)] {
        let settings = SimulationSettings { eps, min_area, solver: SolverKind::GaussSeidel, ..Default::default() };
        let t = std::time::Instant::now();
        let s = simulate(&scene, &settings, &Progress::new(true));
        let r = &s.report;
        println!("eps {eps:e} min {min_area:e}: leaves {} links {} emitted {:.3} absorbed {:?} {:.2}s", s.hierarchy.leaf_count(), s.hierarchy.link_count(), r.emitted_power.r, r.absorbed_power.to_array().map(|a| (a / r.emitted_power.r - 1.0) * 100.0), t.elapsed().as_secs_f64());
    }
}

//! `radiosity audit`: solve, then audit the links into chosen polygons against an unbiased
//! Monte Carlo estimate with visibility (`measures::link_audit`): which sources the couplings see too
//! bright or too dark, by how many standard errors; or the whole transport (`--transport`), or the
//! links' closure (`--closure`).

use super::args::{SceneArgs, SolveArgs};
use crate::measures::link_audit::{
    audit_closure, audit_links, audit_transport, AuditSettings, AuditedSource, SourceRow,
};
use crate::pipeline::simulate;
use crate::progress::Progress;
use anyhow::Result;
use clap::Args;

#[derive(Args, Debug)]
pub struct AuditCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    /// Audit the links into the elements of this polygon (its index, as `probe` prints it);
    /// repeatable; none: every polygon.
    #[arg(long = "polygon", value_name = "N")]
    pub polygons: Vec<usize>,
    /// Independent point pairs (one visibility ray each) per link.
    #[arg(long, default_value_t = 256, value_name = "N", value_parser = super::args::count(2, 1_000_000))]
    pub samples: usize,
    /// Most links to audit: more stops with an error.
    #[arg(long, default_value_t = 200_000, value_name = "N", value_parser = super::args::count(1, 100_000_000))]
    pub max_links: usize,
    /// Source polygons listed (largest differences first).
    #[arg(long, default_value_t = 20, value_name = "N")]
    pub rows: usize,
    /// Audit the transport instead: each polygon side's reflected light as solved against one
    /// unbiased gather of the solution by cosine rays (all couplings, cluster links included).
    #[arg(long)]
    pub transport: bool,
    /// Cosine rays per polygon side for --transport (each with a point on the emitters). Near a small
    /// lamp the direct part's kernel is heavy-tailed and few rays understate the standard error.
    #[arg(long, default_value_t = 65_536, value_name = "N", value_parser = super::args::count(2, 100_000_000))]
    pub transport_rays: usize,
    /// Audit the links' closure instead: the total factor each leaf gathers in a white furnace over
    /// the solution's own links (1 at most in an open scene, 1 in a closed one, up to the couplings'
    /// cubature error); the leaves that gather most are listed (of the --polygon ones, if given).
    #[arg(long, conflicts_with = "transport")]
    pub closure: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

impl AuditCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        let (scene, name) = self.scene.load_for_solving(progress)?;
        for &polygon in &self.polygons {
            anyhow::ensure!(
                polygon < scene.polygons.len(),
                "--polygon {polygon}: {name} has {} polygons",
                scene.polygons.len()
            );
        }
        let settings = self.solve.settings(seed)?;
        let solution = simulate(&scene, &settings, progress)?;
        if self.transport {
            return self.print_transport(&name, &scene, &solution, seed);
        }
        if self.closure {
            return self.print_closure(&name, &solution.hierarchy);
        }
        let audit = audit_links(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &AuditSettings {
                polygons: self.polygons.clone(),
                samples: self.samples,
                max_links: self.max_links,
                seed,
            },
        )?;
        if self.json {
            outln!("{}", serde_json::to_string_pretty(&audit)?)?;
            return Ok(());
        }
        let pushed = audit.into_clusters.links > 0;
        outln!(
            "# {name}: light carried by {} links (Σ A_i F_ij L_j, luminance; source `cN`: cluster N), \
             coupled against {} point pairs each{}",
            audit.total.links,
            self.samples,
            if pushed {
                format!(
                    "; `pushed`: what the clusters above these polygons push down to them, against \
                     their {} links' sources (not in the total)",
                    audit.into_clusters.links
                )
            } else {
                String::new()
            }
        )?;
        outln!(
            "{:>9} {:>6} {:>12} {:>12} {:>10} {:>8} {:>7}",
            "source",
            "links",
            "coupled",
            "estimated",
            "std.err",
            "ratio",
            "z"
        )?;
        let line = |row: &SourceRow| {
            outln!(
                "{:>9} {:>6} {:>12.4e} {:>12.4e} {:>10.2e} {:>8.4} {:>7.1}",
                row.source.to_string(),
                row.links,
                row.coupled,
                row.estimated,
                row.standard_error,
                row.coupled / row.estimated,
                row.z()
            )
        };
        for row in audit.rows.iter().take(self.rows) {
            line(row)?;
        }
        line(&audit.total)?;
        if pushed {
            line(&audit.into_clusters)?;
        }
        // What the listed clusters hold, so that a row can be traced back to the scene.
        let h = &solution.hierarchy;
        for row in audit.rows.iter().take(self.rows) {
            if let AuditedSource::Cluster { element } = row.source {
                let cluster = h.cluster(element).expect("a cluster");
                let polygons: std::collections::BTreeSet<usize> = h
                    .contents(cluster)
                    .iter()
                    .map(|&s| h.patch_of(s).polygon)
                    .collect();
                let shown: Vec<String> = polygons.iter().take(8).map(|p| p.to_string()).collect();
                let more = polygons.len().saturating_sub(shown.len());
                outln!(
                    "# c{element}: {} patches of polygons {}{}",
                    h.contents(cluster).len(),
                    shown.join(", "),
                    if more > 0 {
                        format!(" and {more} more")
                    } else {
                        String::new()
                    }
                )?;
            }
        }
        Ok(())
    }

    fn print_closure(&self, name: &str, h: &crate::hierarchy::Hierarchy) -> Result<()> {
        anyhow::ensure!(
            h.elements.iter().any(|e| !e.links.is_empty()),
            "{name}: the solution has no links to audit (the closure audit needs the deterministic \
             method's link hierarchy)"
        );
        let mut audit = audit_closure(h);
        if !self.polygons.is_empty() {
            audit.rows.retain(|r| self.polygons.contains(&r.polygon));
        }
        if self.json {
            outln!("{}", serde_json::to_string_pretty(&audit)?)?;
            return Ok(());
        }
        outln!(
            "# {name}: closure of the links, Σ F gathered per leaf in a white furnace: {} leaves, \
             mean by area {:.4}, largest {:.4}, above 1.02: {}, above 1.1: {}, above 1.5: {}",
            audit.rows.len(),
            audit.area_mean(),
            audit.largest(),
            audit.above(1.02),
            audit.above(1.1),
            audit.above(1.5)
        )?;
        outln!(
            "{:>9} {:>9} {:>30} {:>10} {:>8} {:>8}",
            "element",
            "side",
            "centre",
            "area",
            "Σ F",
            "pushed"
        )?;
        for row in audit.rows.iter().take(self.rows) {
            let [x, y, z] = row.centre;
            outln!(
                "{:>9} {:>9} {:>30} {:>10.3e} {:>8.4} {:>8.4}",
                row.element,
                format!("{}{}", row.polygon, if row.front { "" } else { "b" }),
                format!("{x:.4} {y:.4} {z:.4}"),
                row.area,
                row.factor,
                row.pushed
            )?;
        }
        Ok(())
    }

    fn print_transport(
        &self,
        name: &str,
        scene: &crate::scene::Scene,
        solution: &crate::pipeline::Solution,
        seed: u64,
    ) -> Result<()> {
        let polygons: Vec<usize> = if self.polygons.is_empty() {
            (0..scene.polygons.len()).collect()
        } else {
            self.polygons.clone()
        };
        let mut rows = audit_transport(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &polygons,
            self.transport_rays,
            seed,
        )?;
        if self.json {
            outln!("{}", serde_json::to_string_pretty(&rows)?)?;
            return Ok(());
        }
        rows.sort_by(|a, b| {
            (b.solved - b.gathered)
                .abs()
                .total_cmp(&(a.solved - a.gathered).abs())
        });
        outln!(
            "# {name}: reflected light per polygon side (luminance × area) as solved against one gather \
             of the solution by {} cosine rays per side",
            self.transport_rays
        )?;
        outln!(
            "{:>9} {:>12} {:>12} {:>10} {:>8} {:>7}",
            "side",
            "solved",
            "gathered",
            "std.err",
            "ratio",
            "z"
        )?;
        let line = |label: String, solved: f64, gathered: f64, error: f64| {
            outln!(
                "{label:>9} {solved:>12.4e} {gathered:>12.4e} {error:>10.2e} {:>8.4} {:>7.1}",
                solved / gathered,
                (solved - gathered) / error
            )
        };
        for row in rows.iter().take(self.rows) {
            line(
                format!("{}{}", row.polygon, if row.front { "" } else { "b" }),
                row.solved,
                row.gathered,
                row.standard_error,
            )?;
        }
        let solved: f64 = rows.iter().map(|r| r.solved).sum();
        let gathered: f64 = rows.iter().map(|r| r.gathered).sum();
        let error = rows
            .iter()
            .map(|r| r.standard_error.powi(2))
            .sum::<f64>()
            .sqrt();
        line("total".to_string(), solved, gathered, error)?;
        Ok(())
    }
}

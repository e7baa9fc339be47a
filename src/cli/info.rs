//! `radiosity info SCENE`: counts, bounds, materials and load warnings, and which polygons lie at a
//! point (the numbers `probe` prints and `audit --polygon` takes).

use super::args::{parse_vec3, SceneArgs};
use crate::geometry::near_field::distance_to_polygon;
use crate::geometry::DVec3;
use anyhow::Result;
use clap::Args;

/// Most polygons `--near` lists.
const MOST_NEAR: usize = 50;

#[derive(Args, Debug)]
pub struct InfoCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// List every material with its reflectance and emission.
    #[arg(long)]
    pub materials: bool,
    /// List every object (MGF `o`, OBJ object or group, glTF node) with its polygons and area: the
    /// names that options naming surfaces match (`--feature-size-for NAME=S`), as materials are.
    #[arg(long)]
    pub objects: bool,
    /// List the polygons within --within of the point X,Y,Z, nearest first: their numbers (as `probe`
    /// prints them and `audit --polygon` takes them, after splitting along contacts), materials,
    /// objects, normals, areas and vertices.
    #[arg(long, value_parser = parse_vec3, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub near: Option<DVec3>,
    /// Distance for --near (default: 10⁻³ of the scene's diagonal, the distance at which `probe`
    /// finds a point's polygon).
    #[arg(long, value_name = "R", requires = "near")]
    pub within: Option<f64>,
}

impl InfoCommand {
    pub fn run(&self) -> Result<()> {
        anyhow::ensure!(
            self.within.is_none_or(|r| r.is_finite() && r >= 0.0),
            "--within must be a non-negative distance"
        );
        let (scene, name, split) = self.scene.load_with_contacts()?;
        for warning in &scene.warnings {
            crate::progress::stderr_line(format_args!("warning: {warning}"));
        }
        outln!("scene: {name}")?;
        outln!("{}", crate::scene::summary(&scene))?;
        match split {
            Some(split) => outln!("contacts:      {split}")?,
            None => outln!("contacts:      not split (--split-contacts off)")?,
        }
        if self.materials {
            for m in &scene.materials {
                let r = m.reflectance;
                let e = m.emission;
                outln!(
                    "material {:<24} rho ({:.3} {:.3} {:.3})  emission ({:.3} {:.3} {:.3})  {}",
                    m.name,
                    r.r,
                    r.g,
                    r.b,
                    e.r,
                    e.g,
                    e.b,
                    if m.two_sided {
                        "two-sided"
                    } else {
                        "one-sided"
                    }
                )?;
            }
        }
        if self.objects {
            let mut counts = vec![(0usize, 0.0f64); scene.objects.len()];
            for p in &scene.polygons {
                if let Some((count, area)) = counts.get_mut(p.object) {
                    *count += 1;
                    *area += p.shape.area();
                }
            }
            for (o, (count, area)) in scene.objects.iter().zip(counts) {
                outln!("object {:<24} {count:>7} polygons  area {area:.4}", o.name)?;
            }
        }
        if let Some(point) = self.near {
            self.print_near(&scene, point)?;
        }
        Ok(())
    }

    /// The `--near` listing.
    fn print_near(&self, scene: &crate::scene::Scene, point: DVec3) -> Result<()> {
        let within = self.within.unwrap_or(1e-3 * scene.bounds().diagonal());
        let mut near: Vec<(f64, usize)> = scene
            .polygons
            .iter()
            .enumerate()
            .map(|(k, p)| (distance_to_polygon(point, &p.shape), k))
            .filter(|&(d, _)| d <= within)
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        outln!(
            "polygons within {within:.4e} of ({:.4}, {:.4}, {:.4}): {}",
            point.x,
            point.y,
            point.z,
            near.len()
        )?;
        for &(distance, k) in near.iter().take(MOST_NEAR) {
            let p = &scene.polygons[k];
            let n = p.shape.normal();
            let vertices: Vec<String> = p
                .shape
                .vertices()
                .iter()
                .map(|v| format!("({:.4}, {:.4}, {:.4})", v.x, v.y, v.z))
                .collect();
            outln!(
                "polygon {k:>7}  distance {distance:.3e}  material {}  object {}  {}  normal \
                 ({:.3}, {:.3}, {:.3})  area {:.4e}  vertices {}",
                scene.material_of(p).name,
                scene.objects.get(p.object).map_or("?", |o| o.name.as_str()),
                if p.two_sided {
                    "two-sided"
                } else {
                    "one-sided"
                },
                n.x,
                n.y,
                n.z,
                p.shape.area(),
                vertices.join(" ")
            )?;
        }
        if near.len() > MOST_NEAR {
            outln!(
                "... and {} more (a smaller --within lists fewer)",
                near.len() - MOST_NEAR
            )?;
        }
        Ok(())
    }
}

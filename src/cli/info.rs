//! `radiosity info SCENE`: counts, bounds, materials and load warnings.

use super::args::SceneArgs;
use anyhow::Result;
use clap::Args;

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
}

impl InfoCommand {
    pub fn run(&self) -> Result<()> {
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
        Ok(())
    }
}

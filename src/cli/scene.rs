//! `radiosity scene NAME -o FILE.mgf`: writes a test scene with a known answer as MGF.

use super::args::parse_vec3;
use crate::geometry::DVec3;
use crate::scene::generators::{self, ShadowGroups};
use crate::scene::{cornell, mgf::writer, Scene};
use anyhow::{ensure, Context, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SceneCommand {
    #[command(subcommand)]
    pub scene: SceneKind,
}

/// Where the MGF goes.
#[derive(Args, Debug)]
pub struct OutputArg {
    /// Output MGF file.
    #[arg(short, long, value_name = "FILE.mgf")]
    pub output: PathBuf,
}

/// Reflectance and emitted radiance of a generated scene.
#[derive(Args, Debug)]
pub struct LightArgs {
    /// Reflectance of the receiving surfaces (0 to < 1).
    #[arg(long, default_value_t = 0.5)]
    pub rho: f64,
    /// Emitted radiance of the source, W/(m² sr).
    #[arg(long, default_value_t = 1.0)]
    pub emission: f64,
}

#[derive(Subcommand, Debug)]
pub enum SceneKind {
    /// Two coaxial parallel squares: the lower reflects, the upper emits (analytic form factor).
    ParallelPlates {
        /// Side of the squares.
        #[arg(long, default_value_t = 1.0)]
        size: f64,
        /// Distance between them.
        #[arg(long, default_value_t = 1.0)]
        distance: f64,
        #[command(flatten)]
        light: LightArgs,
        #[command(flatten)]
        out: OutputArg,
    },
    /// Two squares at a right angle sharing an edge: the horizontal reflects, the vertical emits.
    PerpendicularPlates {
        /// Side of the squares.
        #[arg(long, default_value_t = 1.0)]
        size: f64,
        #[command(flatten)]
        light: LightArgs,
        #[command(flatten)]
        out: OutputArg,
    },
    /// Closed box whose faces all reflect rho and emit E: the radiance is E / (1 - rho) everywhere.
    Furnace {
        /// Box side, or its three sides "x,y,z".
        #[arg(long, default_value = "1")]
        size: String,
        #[command(flatten)]
        light: LightArgs,
        #[command(flatten)]
        out: OutputArg,
    },
    /// The built-in Cornell box (published geometry, millimetres).
    Cornell {
        #[command(flatten)]
        out: OutputArg,
    },
    /// Sillion–Drettakis Figures 1 and 9: a wall lit by a small source through four groups of cubes.
    ShadowGroups {
        /// Cube size of each group, left to right.
        #[arg(long, value_delimiter = ',', default_value = "0.03,0.06,0.12,0.24")]
        cube_sizes: Vec<f64>,
        /// Grid pitch over cube size inside a group (2: a quarter of the footprint is covered).
        #[arg(long, default_value_t = ShadowGroups::default().spacing)]
        spacing: f64,
        /// Side of the square footprint of each group.
        #[arg(long, default_value_t = ShadowGroups::default().group_width)]
        group_width: f64,
        /// Gap between neighbouring groups.
        #[arg(long, default_value_t = ShadowGroups::default().group_gap)]
        group_gap: f64,
        /// Distance of the cube centres from the wall.
        #[arg(long, default_value_t = ShadowGroups::default().cube_distance)]
        distance: f64,
        /// Distance of the source from the wall.
        #[arg(long, default_value_t = ShadowGroups::default().light_distance)]
        light_distance: f64,
        /// Side of the square source.
        #[arg(long, default_value_t = ShadowGroups::default().light_size)]
        light_size: f64,
        /// Reflectance of the wall (and floor).
        #[arg(long, default_value_t = ShadowGroups::default().wall_reflectance)]
        rho: f64,
        /// Reflectance of the cubes.
        #[arg(long, default_value_t = ShadowGroups::default().cube_reflectance)]
        cube_rho: f64,
        /// Emitted radiance of the source, W/(m² sr).
        #[arg(long, default_value_t = ShadowGroups::default().emission)]
        emission: f64,
        /// Add a floor under the wall.
        #[arg(long)]
        floor: bool,
        #[command(flatten)]
        out: OutputArg,
    },
    /// A hall of boxes lit by ceiling panels, of about the given number of polygons (for scaling runs).
    BoxHall {
        /// About this many polygons (five per box).
        #[arg(long, default_value_t = 10_000)]
        polygons: usize,
        #[command(flatten)]
        out: OutputArg,
    },
}

fn check_light(light: &LightArgs) -> Result<()> {
    ensure!(
        (0.0..1.0).contains(&light.rho),
        "--rho must be in [0, 1), not {}",
        light.rho
    );
    ensure!(
        light.emission.is_finite() && light.emission >= 0.0,
        "--emission must be >= 0, not {}",
        light.emission
    );
    Ok(())
}

fn positive(what: &str, v: f64) -> Result<()> {
    ensure!(v.is_finite() && v > 0.0, "{what} must be positive, not {v}");
    Ok(())
}

impl SceneCommand {
    pub fn run(&self) -> Result<()> {
        let (scene, out): (Scene, &OutputArg) = match &self.scene {
            SceneKind::ParallelPlates {
                size,
                distance,
                light,
                out,
            } => {
                check_light(light)?;
                positive("--size", *size)?;
                positive("--distance", *distance)?;
                let scene =
                    generators::parallel_plates(*size, *distance, light.rho, light.emission);
                (scene, out)
            }
            SceneKind::PerpendicularPlates { size, light, out } => {
                check_light(light)?;
                positive("--size", *size)?;
                let scene = generators::perpendicular_plates(*size, light.rho, light.emission);
                (scene, out)
            }
            SceneKind::Furnace { size, light, out } => {
                check_light(light)?;
                let dims = if size.contains(',') {
                    parse_vec3(size).context("--size")?
                } else {
                    let s: f64 = size
                        .trim()
                        .parse()
                        .with_context(|| format!("--size: '{size}' is not a number"))?;
                    DVec3::splat(s)
                };
                for v in dims.to_array() {
                    positive("--size", v)?;
                }
                (generators::furnace(dims, light.rho, light.emission), out)
            }
            SceneKind::Cornell { out } => (cornell::cornell_box(), out),
            SceneKind::ShadowGroups {
                cube_sizes,
                spacing,
                group_width,
                group_gap,
                distance,
                light_distance,
                light_size,
                rho,
                cube_rho,
                emission,
                floor,
                out,
            } => {
                let groups = ShadowGroups {
                    cube_sizes: cube_sizes.clone(),
                    spacing: *spacing,
                    group_width: *group_width,
                    group_gap: *group_gap,
                    cube_distance: *distance,
                    light_distance: *light_distance,
                    light_size: *light_size,
                    emission: *emission,
                    wall_reflectance: *rho,
                    cube_reflectance: *cube_rho,
                    floor: *floor,
                };
                groups
                    .validate()
                    .map_err(|e| anyhow::anyhow!("shadow-groups: {e}"))?;
                (groups.scene(), out)
            }
            SceneKind::BoxHall { polygons, out } => {
                ensure!(
                    (1..=50_000_000).contains(polygons),
                    "--polygons must be in 1..=50000000, not {polygons}"
                );
                (generators::BoxHall::with_polygons(*polygons).scene(), out)
            }
        };
        writer::save(&scene, &out.output)?;
        outln!(
            "wrote {}: {} polygons, {} objects, {} materials",
            out.output.display(),
            scene.polygons.len(),
            scene.objects.len(),
            scene.materials.len()
        )?;
        Ok(())
    }
}

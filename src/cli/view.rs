//! `radiosity view`: solve, write the interactive viewer page and open it in the default browser.

use super::args::{CameraArgs, SceneArgs, SolveArgs, ToneArgs};
use crate::output::render::{render_with, RenderOptions, Shading};
use crate::output::viewer::{write_page, Page, ViewerMesh, DEFAULT_MAX_TRIANGLES};
use crate::pipeline::simulate;
use crate::progress::Progress;
use anyhow::{Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

#[derive(Args, Debug)]
pub struct ViewCommand {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
    /// The initial view (reset with R in the page); --width/--height set the image the automatic
    /// exposure is measured on, as `render` would draw it.
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub tone: ToneArgs,
    /// Seamless (the default): each element's basis expansion without its small steps at element
    /// edges; basis: the expansion itself; continuous: without any steps; flat: element averages;
    /// smooth: vertex values (Gouraud).
    #[arg(long, value_enum, default_value_t = Shading::Seamless)]
    pub shading: Shading,
    /// The page to write (default: SCENE.html in a new directory under the system's temporary directory).
    #[arg(long, value_name = "FILE.html")]
    pub out: Option<PathBuf>,
    /// Only write the page and print its path; do not start a browser.
    #[arg(long)]
    pub no_open: bool,
    /// Most triangles in the page.
    #[arg(long, default_value_t = DEFAULT_MAX_TRIANGLES, value_name = "N", value_parser = super::args::count(1, 1 << 28))]
    pub max_triangles: usize,
}

impl ViewCommand {
    pub fn run(&self, seed: u64, progress: &Progress) -> Result<()> {
        let tone = self.tone.tone_map()?;
        if let Some(out) = &self.out {
            super::args::check_output("--out", out, self.scene.scene.as_slice())?;
            let ext = out.extension().and_then(|e| e.to_str()).unwrap_or("");
            anyhow::ensure!(
                ext.eq_ignore_ascii_case("html") || ext.eq_ignore_ascii_case("htm"),
                "--out {}: expected an .html file",
                out.display()
            );
        }
        let (scene, name) = self.scene.load_for_solving(progress)?;
        if let Some(out) = &self.out {
            super::args::check_output("--out", out, &scene.sources)?;
        }
        let settings = self.solve.settings(seed)?;
        let camera = self.camera.camera(&scene, 512)?;
        let mut solution = simulate(&scene, &settings, progress)?;
        solution.hierarchy.release_solver_state();
        let mesh = ViewerMesh::new(&solution.hierarchy, self.shading, None, self.max_triangles)?;
        // The exposure `render` would choose for this view (pixel centres: one sample per pixel).
        let image = render_with(
            &solution.hierarchy,
            solution.visibility.as_ref(),
            &camera,
            &RenderOptions {
                shading: self.shading,
                ..Default::default()
            },
            None,
        );
        let page = Page {
            title: &name,
            camera: &camera,
            curve: tone.curve,
            exposure: tone.exposure_scale(image.pixels.iter().copied()),
            shading: self.shading,
        };
        let path = match &self.out {
            Some(out) => out.clone(),
            None => temporary_page(self.scene.scene.as_deref())?,
        };
        write_page(&path, &mesh, &page)?;
        outln!("{}", path.display())?;
        if !self.no_open && !open_in_browser(&path) && !progress.quiet {
            crate::progress::stderr_line(format_args!(
                "no browser opener (xdg-open, open, start) found: open the file above"
            ));
        }
        Ok(())
    }
}

/// `radiosity-view-PID/NAME.html` under the temporary directory, named after the scene file.
fn temporary_page(scene: Option<&Path>) -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("radiosity-view-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let stem = scene
        .and_then(|p| p.file_stem())
        .and_then(|s| s.to_str())
        .unwrap_or("cornell");
    Ok(dir.join(format!("{stem}.html")))
}

/// Hands the page to the desktop's opener; false when there is none. The opener is not waited for.
fn open_in_browser(path: &Path) -> bool {
    let (program, arguments): (&str, &[&str]) = if cfg!(target_os = "macos") {
        ("open", &[])
    } else if cfg!(windows) {
        ("cmd", &["/C", "start", ""])
    } else {
        ("xdg-open", &[])
    };
    Command::new(program)
        .args(arguments)
        .arg(path)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .is_ok()
}

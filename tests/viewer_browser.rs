//! The interactive viewer page (`render --export page.html`, `radiosity view`): self-contained and
//! bounded, and, in headless Chromium (`scripts/install-chromium.sh`), a screenshot of the page at load
//! equals our own PNG render of the same view.
//!
//! Error model of the screenshot comparison. The page opened with `#bare` draws without antialiasing, so
//! each pixel is the fragment at the pixel centre, the sample `render --spp 1` takes. At a centre inside a
//! triangle the rasteriser interpolates, perspective-correctly, the vertex values of the leaf's sampled
//! expansion; the ray caster evaluates the same expansion at the same point. With the linear basis both
//! are the same affine function on a triangle and on a parallelogram; the Cornell box's quads are not
//! quite parallelograms (3 mm out of 550 at the root), and a leaf's twist shrinks by 4 per level, so the
//! split along the diagonal moves values by far less than an 8-bit code. Both then round the same
//! tone-mapped value to 8 bits; single against double precision can tip the rounding, so a pixel may
//! differ by 1 code per channel and by no more. Pixels whose 3x3 neighbourhood (in our own ray casting)
//! sees more than one leaf element are where the rasteriser's vertex snapping and its tie rules may hand
//! the centre to the neighbouring element, so they may jump by the discontinuity between elements (the
//! basis expansion is discontinuous): they are counted separately, with a bound from the snapping
//! precision (below). Snapping also moves the interpolant by up to [`SNAP`] pixels, which on a steep
//! gradient (a contact shadow: 50 codes per pixel) is worth a few codes: the tolerance of a pixel is
//! 1 code plus `SNAP` times the PNG's own slope there (codes per pixel, towards neighbours on the same
//! leaf). Silhouettes and creases (more than one patch, or background, in the 3x3
//! neighbourhood) are left out: there the two renderers may see different surfaces.

use radiosity::geometry::{DVec3, Shape};
use radiosity::hierarchy::Hierarchy;
use radiosity::output::camera::Camera;
use radiosity::output::render::{render, RenderOptions, Shading};
use radiosity::output::tonemap::{to_srgb8, ToneMap};
use radiosity::output::viewer::{page_html, write_page, Page, ViewerMesh};
use radiosity::output::VertexRadiosity;
use radiosity::pipeline::{simulate, SimulationSettings, Solution};
use radiosity::progress::Progress;
use radiosity::scene::cornell::cornell_box;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

// Headless Chromium lays a page out in a window at least 500 pixels wide, then resizes the view to the
// screenshot's size: the page redraws on resize, and the image is wider than that minimum.
const WIDTH: usize = 640;
const HEIGHT: usize = 480;
/// How far, in pixels, the rasteriser may move a vertex or an edge: GL ES requires at least 4 bits of
/// sub-pixel precision (SUBPIXEL_BITS), so positions snap to a 1/16 pixel grid.
const SNAP: f64 = 1.0 / 16.0;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-viewer-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The Cornell box, linear basis (the render default), refined by the power oracle to a few hundred
/// leaves: elements several pixels wide at this image size.
fn solved_cornell() -> Solution {
    let settings = SimulationSettings {
        basis: radiosity::bases::BasisKind::Linear,
        eps: 1e-3,
        ..Default::default()
    };
    simulate(&cornell_box(), &settings, &Progress::new(true)).unwrap()
}

fn camera() -> Camera {
    Camera::new(&cornell_box().camera.unwrap(), WIDTH, HEIGHT)
}

/// The browser named by RADIOSITY_CHROMIUM, else Debian's `/usr/bin/chromium`, else `chromium` or
/// `chromium-browser` on the PATH.
fn chromium() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("RADIOSITY_CHROMIUM") {
        return Some(PathBuf::from(path));
    }
    let debian = PathBuf::from("/usr/bin/chromium");
    if debian.is_file() {
        return Some(debian);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .flat_map(|dir| ["chromium", "chromium-browser"].map(|name| dir.join(name)))
        .find(|p| p.is_file())
}

/// The browser, or `None` (the test is skipped, and says so) when there is none and
/// RADIOSITY_REQUIRE_BROWSER is not 1; with it, a missing browser fails the test.
fn browser_or_skip() -> Option<PathBuf> {
    let browser = chromium();
    if browser.is_none() {
        assert!(
            std::env::var("RADIOSITY_REQUIRE_BROWSER").as_deref() != Ok("1"),
            "RADIOSITY_REQUIRE_BROWSER=1 but no Chromium: run scripts/install-chromium.sh"
        );
        eprintln!("skipped: no Chromium (scripts/install-chromium.sh installs it)");
    }
    browser
}

/// Screenshot of `page` (with URL fragment `fragment`) at `WIDTH` x `HEIGHT`, and the browser's log.
fn screenshot(
    browser: &Path,
    page: &Path,
    fragment: &str,
    dir: &Path,
) -> (image::RgbImage, String) {
    let shot = dir.join("screenshot.png");
    let profile = dir.join("profile");
    let url = format!(
        "file://{}#{fragment}",
        page.canonicalize().unwrap().display()
    );
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--force-color-profile=srgb",
            "--force-device-scale-factor=1",
            "--enable-logging=stderr",
            // Nothing may leave the machine: every connection goes to a proxy that does not exist.
            "--proxy-server=127.0.0.1:9",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--window-size={WIDTH},{HEIGHT}"))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(&url)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("starting {}: {e}", browser.display()));
    // A guard against a hung browser, not a timing assertion.
    let deadline = Instant::now() + Duration::from_secs(180);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("{} did not finish within 3 minutes", browser.display());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let output = child.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&output.stdout).to_string()
        + &String::from_utf8_lossy(&output.stderr);
    let image = image::open(&shot)
        .unwrap_or_else(|e| panic!("no screenshot ({e}); browser log:\n{log}"))
        .to_rgb8();
    (image, log)
}

/// Per pixel centre: the patch and the leaf element our ray caster sees (None: background or the black
/// back of a one-sided polygon).
fn visible_leaves(solution: &Solution, camera: &Camera) -> Vec<Option<(u32, u32)>> {
    let mut out = Vec::with_capacity(WIDTH * HEIGHT);
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
            let seen = solution
                .visibility
                .intersect(&ray, 0.0, f64::INFINITY)
                .and_then(|hit| {
                    let patch = solution.hierarchy.patch_for_side(hit.polygon, hit.front)?;
                    let normal = solution.hierarchy.patches[patch as usize].normal;
                    let origin = solution.hierarchy.patch_shape(patch).vertices()[0];
                    let p = ray.at(hit.t);
                    let p: DVec3 = p - normal * normal.dot(p - origin);
                    Some((patch, solution.hierarchy.locate(patch, p)))
                });
            out.push(seen);
        }
    }
    out
}

/// Triangles and vertices of the page's mesh with `cells` grid cells per leaf edge: an n x n grid has
/// n² triangles and (n + 1)(n + 2)/2 points on a triangle, 2n² and (n + 1)² on a quad; a leaf with
/// T-vertices is a fan, one triangle per outline point plus the centre.
fn expected_counts(
    hierarchy: &Hierarchy,
    vertices: &VertexRadiosity,
    cells: usize,
) -> (usize, usize) {
    let n = cells;
    hierarchy.leaves().iter().fold((0, 0), |(t, p), &leaf| {
        match (vertices.outline(leaf), hierarchy.element(leaf).shape()) {
            (Some(outline), _) => (t + outline.len(), p + outline.len() + 1),
            (None, Shape::Triangle(_)) => (t + n * n, p + (n + 1) * (n + 2) / 2),
            (None, Shape::Quad(_)) => (t + 2 * n * n, p + (n + 1) * (n + 1)),
        }
    })
}

#[test]
fn page_is_self_contained_and_bounded() {
    let solution = solved_cornell();
    let camera = camera();
    let vertices = VertexRadiosity::new(&solution.hierarchy);
    let mesh = ViewerMesh::new(
        &solution.hierarchy,
        Shading::Basis,
        Some(&vertices),
        usize::MAX,
    )
    .unwrap();
    // Linear basis: one grid cell per leaf, so every leaf is its own one or two triangles, except the
    // leaves with T-vertices: a fan through their outline.
    assert!(
        vertices.fanned_leaf_count() > 0,
        "the test should cover fans"
    );
    let (triangles, points) = expected_counts(&solution.hierarchy, &vertices, 1);
    assert_eq!(mesh.triangles.len(), triangles);
    assert_eq!(mesh.positions.len(), points);
    let page = Page {
        title: "Cornell <box> & \"friends\"",
        camera: &camera,
        curve: radiosity::output::tonemap::Curve::Filmic,
        exposure: 0.5,
        shading: Shading::Basis,
    };
    let html = page_html(&mesh, &page).unwrap();
    // Nothing to fetch: a policy that forbids any load, and no address in the page (outside the
    // base64 data blocks, which hold nothing else).
    let mut text = String::new();
    let mut rest = html.as_str();
    while let Some(start) = rest.find("type=\"application/octet-stream\"") {
        let open = start + rest[start..].find('>').unwrap() + 1;
        let close = open + rest[open..].find("</script>").unwrap();
        assert!(rest[open..close]
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"+/=".contains(&b)));
        text.push_str(&rest[..open]);
        rest = &rest[close..];
    }
    text.push_str(rest);
    assert!(text.contains("Content-Security-Policy\" content=\"default-src 'none';"));
    for needle in [
        "http:", "https:", "ws:", "wss:", "src=", "href=", "@import", "url(", "fetch(",
    ] {
        assert!(!text.contains(needle), "the page mentions {needle}");
    }
    assert!(html.contains(
        "<title>Cornell &lt;box&gt; &amp; &quot;friends&quot; - radiosity viewer</title>"
    ));
    assert!(!html.contains("<box>"));
    // The budget stops a page that would be too large, with the count and the option.
    let error = ViewerMesh::new(&solution.hierarchy, Shading::Basis, None, triangles - 1)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains(&format!("{triangles} triangles")) && error.contains("--max-triangles"),
        "{error}"
    );
    // Higher-order bases are sampled on a finer grid: cubic, 3 x 3 cells per leaf.
    let settings = SimulationSettings {
        basis: radiosity::bases::BasisKind::Cubic,
        eps: 1e-2,
        ..Default::default()
    };
    let cubic = simulate(&cornell_box(), &settings, &Progress::new(true)).unwrap();
    let vertices = VertexRadiosity::new(&cubic.hierarchy);
    let mesh = ViewerMesh::new(
        &cubic.hierarchy,
        Shading::Basis,
        Some(&vertices),
        usize::MAX,
    )
    .unwrap();
    let (triangles, points) = expected_counts(&cubic.hierarchy, &vertices, 3);
    assert_eq!(mesh.triangles.len(), triangles);
    assert_eq!(mesh.positions.len(), points);
}

#[test]
fn chromium_screenshot_of_the_page_matches_the_png_render() {
    let Some(browser) = browser_or_skip() else {
        return;
    };
    let dir = temp_dir("screenshot");
    let solution = solved_cornell();
    let camera = camera();
    let options = RenderOptions {
        shading: Shading::Basis,
        samples_per_pixel: 1,
        ..Default::default()
    };
    let image = render(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        &camera,
        &options,
    );
    let tone = ToneMap::default();
    let expected = to_srgb8(&image, &tone);
    let mesh = ViewerMesh::new(&solution.hierarchy, Shading::Basis, None, usize::MAX).unwrap();
    let page = dir.join("cornell.html");
    write_page(
        &page,
        &mesh,
        &Page {
            title: "Cornell box",
            camera: &camera,
            curve: tone.curve,
            exposure: tone.exposure_scale(image.pixels.iter().copied()),
            shading: Shading::Basis,
        },
    )
    .unwrap();
    let (shot, log) = screenshot(&browser, &page, "bare", &dir);
    assert_eq!(
        shot.dimensions(),
        (WIDTH as u32, HEIGHT as u32),
        "browser log:\n{log}"
    );
    // The page tried to load nothing (the policy would have refused it, and said so).
    assert!(
        !log.contains("Content Security Policy") && !log.contains("Refused to"),
        "{log}"
    );
    let _ = expected.save(dir.join("expected.png"));

    let seen = visible_leaves(&solution, &camera);
    let neighbourhood = |x: usize, y: usize| {
        let mut cells = Vec::with_capacity(9);
        for ny in y.saturating_sub(1)..=(y + 1).min(HEIGHT - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(WIDTH - 1) {
                cells.push(seen[ny * WIDTH + nx]);
            }
        }
        cells
    };
    let (mut interior, mut interior_sum) = (0usize, 0.0);
    let (mut edges, mut edges_off) = (0usize, 0usize);
    let mut offenders = Vec::new();
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let cells = neighbourhood(x, y);
            let Some(centre) = seen[y * WIDTH + x] else {
                continue;
            };
            if cells.iter().any(|c| c.map(|c| c.0) != Some(centre.0)) {
                continue; // silhouette or crease
            }
            let a = expected.get_pixel(x as u32, y as u32).0;
            let b = shot.get_pixel(x as u32, y as u32).0;
            // The PNG's slope here, in codes per pixel, between this pixel and its neighbours on the
            // same leaf (the same affine function).
            let mut slope = [0i32; 3];
            for (dx, dy) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
                let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                if nx < 0 || ny < 0 || nx >= WIDTH as i32 || ny >= HEIGHT as i32 {
                    continue;
                }
                if seen[ny as usize * WIDTH + nx as usize] != Some(centre) {
                    continue;
                }
                let n = expected.get_pixel(nx as u32, ny as u32).0;
                for k in 0..3 {
                    slope[k] = slope[k].max((i32::from(n[k]) - i32::from(a[k])).abs());
                }
            }
            let off = (0..3).any(|k| {
                let difference = f64::from((i32::from(a[k]) - i32::from(b[k])).abs());
                difference > 1.0 + SNAP * f64::from(slope[k])
            });
            let difference = (0..3)
                .map(|k| (i32::from(a[k]) - i32::from(b[k])).abs())
                .max()
                .unwrap();
            if cells.iter().all(|&c| c == Some(centre)) {
                interior += 1;
                if off {
                    offenders.push((x, y, a, b));
                }
                interior_sum += f64::from(difference);
            } else {
                edges += 1;
                edges_off += usize::from(off);
            }
        }
    }
    eprintln!(
        "interior pixels {interior}: {} beyond the bound, mean difference {:.3} codes; element-edge \
         pixels {edges}: {edges_off} beyond the bound",
        offenders.len(),
        interior_sum / interior as f64
    );
    // Enough of the picture is compared to mean something.
    assert!(
        interior > WIDTH * HEIGHT / 10,
        "only {interior} interior pixels"
    );
    assert!(
        offenders.is_empty(),
        "{} interior pixels differ by more than rounding and snapping (x, y, png, page): {:?}; see {}",
        offenders.len(),
        &offenders[..offenders.len().min(10)],
        dir.display()
    );
    // Rounding: a difference of a code where a value straddles a step, rarely (the slope term only
    // matters on the steepest gradients), so well below half a code on average.
    assert!(interior_sum / interior as f64 <= 0.5);
    // Beside an element edge, a pixel centre within SNAP of the edge may change element: the 3x3 band
    // is about 3 pixels wide per edge, of which 2 SNAP is that close, so at most 2 SNAP / 3 of the band.
    assert!(
        edges_off as f64 <= 2.0 * SNAP / 3.0 * edges as f64,
        "{edges_off} of {edges} element-edge pixels differ; see {}",
        dir.display()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn render_export_and_view_write_the_page() {
    let dir = temp_dir("cli");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_radiosity"))
            .args(args)
            .args([
                "--quiet", "--eps", "1e-2", "--width", "32", "--height", "24",
            ])
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let out = run(&[
        "render", "-o", "c.png", "--export", "c.html", "--export", "c.ply",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.join("c.html")).unwrap();
    assert!(html.starts_with("<!doctype html>") && html.contains("\"fov\":39.3"));
    // `view` writes where it is told, prints the path and, with --no-open, starts nothing.
    let out = run(&["view", "--no-open", "--out", "v.html"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "v.html");
    assert!(dir.join("v.html").is_file());
    // By default into a fresh temporary directory.
    let out = run(&["view", "--no-open"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    assert!(
        printed.starts_with(std::env::temp_dir()) && printed.is_file(),
        "{printed:?}"
    );
    std::fs::remove_dir_all(printed.parent().unwrap()).unwrap();
    // Refusals: a scene file as output, an unknown export type, a page over its triangle budget.
    for (args, expected) in [
        (&["view", "--no-open", "--out", "x.mgf"][..], "scene file"),
        (&["view", "--no-open", "--out", "x.png"][..], ".html"),
        (&["render", "-o", "d.png", "--export", "d.txt"][..], ".html"),
        (
            &[
                "view",
                "--no-open",
                "--out",
                "w.html",
                "--max-triangles",
                "1",
            ][..],
            "--max-triangles",
        ),
    ] {
        let out = run(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(expected),
            "{args:?}: {stderr}"
        );
    }
    assert!(!dir.join("w.html").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// sRGB code (0–255) to linear (IEC 61966-2-1), for a code moved by `offset` (quantisation bounds).
fn srgb_to_linear(code: u8, offset: f64) -> f64 {
    let c = ((f64::from(code) + offset) / 255.0).clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Share of pixels whose channels differ by more than 2 codes (rasterisation may move an edge pixel).
fn changed_share(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    let changed = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| p.0.iter().zip(q.0).any(|(&x, y)| x.abs_diff(y) > 2))
        .count();
    changed as f64 / (a.width() * a.height()) as f64
}

/// The viewer's controls, driven by replayed input events through the page's own handlers (`#play=`):
/// - orbiting (drag), zooming (wheel) and the exposure slider change the image (over 5% of pixels);
/// - orbiting right, up, down and left by the same amounts, zooming out and in, and R after an orbit
///   and an exposure change each return to the start image (under 0.1% of pixels changed: rounding
///   of the rotations may move an edge pixel);
/// - one stop up doubles every pixel in linear space: with the linear tone curve, wherever the start
///   image is unclipped after doubling (codes 40 to 170), the ratio of the decoded values lies within
///   the bounds that half a code of quantisation on either side allows, widened by 1% for the GPU's
///   single-precision arithmetic.
#[test]
fn viewer_controls_respond_to_replayed_input() {
    let Some(browser) = browser_or_skip() else {
        return;
    };
    let dir = temp_dir("controls");
    let solution = solved_cornell();
    let camera = camera();
    let mesh = ViewerMesh::new(&solution.hierarchy, Shading::Basis, None, usize::MAX).unwrap();
    let page = dir.join("cornell.html");
    let tone = ToneMap::default();
    let image = render(
        &solution.hierarchy,
        solution.visibility.as_ref(),
        &camera,
        &RenderOptions::default(),
    );
    write_page(
        &page,
        &mesh,
        &Page {
            title: "Cornell box",
            camera: &camera,
            curve: radiosity::output::tonemap::Curve::Linear,
            exposure: tone.exposure_scale(image.pixels.iter().copied()),
            shading: Shading::Basis,
        },
    )
    .unwrap();
    let shot = |steps: &str| {
        let fragment = if steps.is_empty() {
            "bare".to_string()
        } else {
            format!("bare&play={steps}")
        };
        let (image, log) = screenshot(&browser, &page, &fragment, &dir);
        assert!(!log.contains("unknown replay step"), "{log}");
        image
    };
    let start = shot("");
    for steps in ["drag:60:0", "wheel:400", "stops:1"] {
        let share = changed_share(&start, &shot(steps));
        assert!(share > 0.05, "{steps}: only {share} of the pixels changed");
    }
    for steps in [
        "drag:60:0;drag:0:25;drag:0:-25;drag:-60:0",
        "wheel:400;wheel:-400",
        "drag:60:0;stops:2;key:r",
    ] {
        let share = changed_share(&start, &shot(steps));
        assert!(share < 0.001, "{steps}: {share} of the pixels changed");
    }
    let brighter = shot("stops:1");
    let mut checked = 0;
    for (a, b) in start.pixels().zip(brighter.pixels()) {
        for (&ca, cb) in a.0.iter().zip(b.0) {
            if !(40..=170).contains(&ca) {
                continue;
            }
            let low = srgb_to_linear(cb, -0.5) / srgb_to_linear(ca, 0.5);
            let high = srgb_to_linear(cb, 0.5) / srgb_to_linear(ca, -0.5);
            assert!(
                low / 1.01 <= 2.0 && 2.0 <= high * 1.01,
                "codes {ca} -> {cb}: ratio in [{low}, {high}]"
            );
            checked += 1;
        }
    }
    assert!(checked > 10_000, "only {checked} channels checked");
}

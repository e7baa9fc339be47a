//! Rendering (flat, smooth, mesh overlay, multi-sampling, thread independence) and illuminated-model export
//! (PLY, GLB) of hand-built hierarchies.

use radiosity::color::Rgb;
use radiosity::geometry::form_factor::point_to_polygon;
use radiosity::geometry::{DVec2, DVec3, Shape};
use radiosity::hierarchy::Hierarchy;
use radiosity::output::camera::Camera;
use radiosity::output::image::Image;
use radiosity::output::tonemap::{to_srgb8, write_png, Curve, Exposure, ToneMap};
use radiosity::output::{
    render, render_with, write_glb, write_ply, Antialias, RenderOptions, Shading, VertexRadiosity,
};
use radiosity::scene::{CameraSpec, Material, Object, Polygon, Scene};
use radiosity::visibility::brute_force::BruteForce;
use radiosity::visibility::Visibility;
use std::path::PathBuf;

fn scene(polygons: Vec<(Shape, usize, bool)>, materials: Vec<Material>) -> Scene {
    Scene {
        polygons: polygons
            .into_iter()
            .map(|(shape, material, two_sided)| Polygon {
                shape,
                material,
                object: 0,
                two_sided,
                under_contact: false,
            })
            .collect(),
        materials,
        objects: vec![Object {
            name: "test".into(),
        }],
        ..Default::default()
    }
}

fn visibility(scene: &Scene) -> BruteForce {
    BruteForce::new(scene.polygons.iter().map(|p| p.shape).collect())
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-output-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The unit floor square (normal +z), refined towards one corner, with leaf radiance a function of the
/// leaf centroid; seen from above by a 64 x 64 camera whose view extends past the floor.
fn floor_setup(two_sided: bool) -> (Scene, Hierarchy) {
    let floor = Shape::Quad([DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]);
    let s = scene(
        vec![(floor, 0, two_sided)],
        vec![Material::diffuse("floor", Rgb::splat(0.5))],
    );
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    let children = h.subdivide(h.patches[0].root);
    let grand = h.subdivide(children[0]);
    h.subdivide(grand[2]);
    for leaf in h.leaves() {
        let c = h.element(leaf).shape().centroid();
        h.radiance_mut(leaf)[0] = Rgb::new(1.0 + c.x, 2.0 + c.y, 0.5 + c.x * c.y);
    }
    (s, h)
}

fn top_camera() -> Camera {
    top_camera_of(64)
}

/// [`top_camera`] with `size` × `size` pixels.
fn top_camera_of(size: usize) -> Camera {
    // Off-centre by a fraction of a pixel so that no pixel centre lies exactly on a leaf edge.
    let spec = CameraSpec {
        eye: DVec3::new(0.5071, 0.4933, 2.0),
        look_at: DVec3::new(0.5071, 0.4933, 0.0),
        up: DVec3::Y,
        fov_degrees: 40.0,
    };
    Camera::new(&spec, size, size)
}

/// `work` on a pool of `threads` threads.
fn on_threads<T: Send>(threads: usize, work: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
        .install(work)
}

/// Where the centre ray of pixel (x, y) meets the plane z = 0: (t, point).
fn floor_hit(camera: &Camera, x: usize, y: usize) -> (f64, DVec3) {
    floor_hit_at(camera, x as f64 + 0.5, y as f64 + 0.5)
}

/// Where the ray through image position (x, y) in pixels meets the plane z = 0: (t, point).
fn floor_hit_at(camera: &Camera, x: f64, y: f64) -> (f64, DVec3) {
    let ray = camera.ray(x, y);
    let t = -ray.origin.z / ray.direction.z;
    (t, ray.at(t))
}

#[test]
fn flat_render_is_the_leaf_radiance_and_misses_are_black() {
    let (s, h) = floor_setup(false);
    let camera = top_camera();
    let image = render(&h, &visibility(&s), &camera, &RenderOptions::default());
    let leaves = h.leaves();
    let (mut on_floor, mut missed) = (0, 0);
    for y in 0..64 {
        for x in 0..64 {
            let (_, p) = floor_hit(&camera, x, y);
            let pixel = image.get(x, y);
            let inside = |lo: DVec3, hi: DVec3, m: f64| {
                p.x > lo.x + m && p.x < hi.x - m && p.y > lo.y + m && p.y < hi.y - m
            };
            if !inside(DVec3::ZERO, DVec3::ONE, -1e-9) {
                assert_eq!(pixel, Rgb::BLACK);
                missed += 1;
                continue;
            }
            // Independent lookup: the axis-aligned leaf square strictly containing the point.
            let Some(&leaf) = leaves.iter().find(|&&l| {
                let b = h.element(l).shape().bounds();
                inside(b.min, b.max, 1e-9)
            }) else {
                continue;
            };
            assert_eq!(pixel, h.average_radiance(leaf), "pixel ({x}, {y})");
            on_floor += 1;
        }
    }
    assert!(on_floor > 1800 && missed > 2000, "{on_floor} {missed}");
}

#[test]
fn smooth_render_is_the_vertex_interpolation_at_the_hit_point() {
    let (s, h) = floor_setup(false);
    let camera = top_camera();
    let vr = VertexRadiosity::new(&h);
    let options = RenderOptions {
        shading: Shading::Smooth,
        ..Default::default()
    };
    let image = render_with(&h, &visibility(&s), &camera, &options, Some(&vr));
    assert_eq!(image, render(&h, &visibility(&s), &camera, &options));
    for y in 0..64 {
        for x in 0..64 {
            let (_, p) = floor_hit(&camera, x, y);
            if !(0.0..=1.0).contains(&p.x) || !(0.0..=1.0).contains(&p.y) {
                continue;
            }
            let expected = vr.evaluate(&h, h.locate(0, p), p);
            let d = (image.get(x, y) - expected).map(f64::abs).max_channel();
            assert!(d < 1e-12, "pixel ({x}, {y})");
        }
    }
}

#[test]
fn back_sides_are_black_when_one_sided_and_their_own_patch_when_two_sided() {
    let below = CameraSpec {
        eye: DVec3::new(0.5, 0.5, -2.0),
        look_at: DVec3::new(0.5, 0.5, 0.0),
        up: DVec3::Y,
        fov_degrees: 20.0,
    };
    let camera = Camera::new(&below, 16, 16);
    let (s, h) = floor_setup(false);
    let image = render(&h, &visibility(&s), &camera, &RenderOptions::default());
    assert!(image.pixels.iter().all(|p| *p == Rgb::BLACK));

    let (s, mut h) = floor_setup(true);
    let back_root = h.patches[1].root;
    h.radiance_mut(back_root)[0] = Rgb::new(0.1, 0.2, 0.3);
    let image = render(&h, &visibility(&s), &camera, &RenderOptions::default());
    // The 20 degree view from 2 below sees only the floor's back: its single leaf.
    assert!(image.pixels.iter().all(|p| *p == Rgb::new(0.1, 0.2, 0.3)));
}

#[test]
fn images_do_not_depend_on_thread_count_and_jitter_is_seeded() {
    let (s, h) = floor_setup(false);
    let camera = top_camera();
    let vis = visibility(&s);
    let options = RenderOptions {
        shading: Shading::Smooth,
        mesh: true,
        samples_per_pixel: 5,
        seed: 42,
        mesh_colour: Rgb::new(9.0, 0.0, 0.0),
        ..Default::default()
    };
    let in_pool = |threads: usize| on_threads(threads, || render(&h, &vis, &camera, &options));
    let one = in_pool(1);
    assert_eq!(one, in_pool(3));
    assert_ne!(
        one,
        render(
            &h,
            &vis,
            &camera,
            &RenderOptions {
                seed: 43,
                ..options
            }
        )
    );
}

/// Both antialiasing modes: stratified samples every pixel; adaptive averages the corners of pixels
/// wholly on (or off) the floor, where they agree, and samples the pixels its edge crosses. At 150
/// rows the floor's far edge lies in the second band of rows whose corners adaptive antialiasing holds
/// at a time, and the image ends in a partial band.
#[test]
fn supersampling_averages_inside_the_pixel() {
    let (s, mut h) = floor_setup(false);
    for id in 0..h.elements.len() as u32 {
        h.radiance_mut(id)[0] = Rgb::splat(2.0);
    }
    for (size, antialias) in [
        (64, Antialias::Stratified),
        (64, Antialias::Adaptive),
        (150, Antialias::Adaptive),
    ] {
        let camera = top_camera_of(size);
        let options = RenderOptions {
            samples_per_pixel: 16,
            antialias,
            ..Default::default()
        };
        let image = render(&h, &visibility(&s), &camera, &options);
        // The image plane is parallel to the floor: a pixel covers an axis-aligned square of it, so its
        // exact floor coverage is an overlap of intervals. 4 x 4 strata err by at most one column (or
        // row) of strata.
        let (mut partial, mut error_sum) = (0, 0.0);
        for y in 0..size {
            for x in 0..size {
                let (_, a) = floor_hit_at(&camera, x as f64, y as f64);
                let (_, b) = floor_hit_at(&camera, x as f64 + 1.0, y as f64 + 1.0);
                let overlap = |lo: f64, hi: f64| {
                    let (lo, hi) = (lo.min(hi), lo.max(hi));
                    (hi.min(1.0) - lo.max(0.0)).max(0.0) / (hi - lo)
                };
                let coverage = overlap(a.x, b.x) * overlap(a.y, b.y);
                let estimate = image.get(x, y).r / 2.0;
                if coverage == 0.0 || coverage == 1.0 {
                    assert_eq!(estimate, coverage, "{antialias:?} ({x}, {y})");
                } else {
                    assert!(
                        (estimate - coverage).abs() <= 0.25 + 1e-12,
                        "{antialias:?} ({x}, {y})"
                    );
                    partial += 1;
                    error_sum += estimate - coverage;
                }
            }
        }
        // Jittered strata are unbiased: the errors average out along the border.
        assert!(partial > 100, "{partial}");
        assert!(
            (error_sum / partial as f64).abs() < 0.03,
            "{antialias:?}: {}",
            error_sum / partial as f64
        );
    }
}

/// Adaptive antialiasing on a smooth field: a pixel whose corners differ by less than the contrast
/// threshold is their mean, which for a field linear across the pixel is its box filter exactly; one
/// across a step is sampled. The image does not depend on the thread count.
#[test]
fn adaptive_antialiasing_averages_smooth_pixels_and_samples_steps() {
    let (s, mut h) = floor_setup(false);
    // One leaf per quarter of the floor, each with its own constant radiance: a step of 40% between
    // the left and right halves, none between top and bottom.
    let leaves = h.leaves();
    assert!(leaves.len() >= 4, "{} leaves", leaves.len());
    for &id in &leaves {
        let centre = h.element(id).shape().centroid();
        h.radiance_mut(id)[0] = Rgb::splat(if centre.x < 0.5 { 1.0 } else { 1.4 });
    }
    let camera = top_camera();
    let vis = visibility(&s);
    let options = RenderOptions {
        samples_per_pixel: 16,
        antialias: Antialias::Adaptive,
        seed: 3,
        ..Default::default()
    };
    let in_pool = |threads: usize| on_threads(threads, || render(&h, &vis, &camera, &options));
    let image = in_pool(1);
    assert_eq!(image, in_pool(3));
    let mut across = 0;
    for y in 0..64 {
        for x in 0..64 {
            let (_, a) = floor_hit_at(&camera, x as f64, y as f64);
            let (_, b) = floor_hit_at(&camera, x as f64 + 1.0, y as f64 + 1.0);
            let inside = |p: f64| (0.0..=1.0).contains(&p);
            if !(inside(a.x) && inside(b.x) && inside(a.y) && inside(b.y)) {
                continue; // the floor's own border
            }
            let value = image.get(x, y).r;
            let (lo, hi) = (a.x.min(b.x), a.x.max(b.x));
            if hi <= 0.5 || lo >= 0.5 {
                // Wholly on one side: the corners' mean is the leaf's radiance.
                assert_eq!(value, if hi <= 0.5 { 1.0 } else { 1.4 }, "({x}, {y})");
            } else {
                // Across the step: sampled, so near the covered fraction (one column of strata).
                let right = (hi - 0.5) / (hi - lo);
                let exact = 1.0 + 0.4 * right;
                assert!((value - exact).abs() <= 0.4 * 0.25 + 1e-12, "({x}, {y})");
                across += 1;
            }
        }
    }
    assert!(across > 10, "{across}");
}

#[test]
fn mesh_lines_follow_leaf_edges_about_a_pixel_wide() {
    let (s, h) = floor_setup(false);
    let camera = top_camera();
    let red = Rgb::new(7.0, 0.0, 0.0);
    let options = RenderOptions {
        mesh: true,
        mesh_colour: red,
        ..Default::default()
    };
    let image = render(&h, &visibility(&s), &camera, &options);
    let (mut lines, mut clear) = (0, 0);
    for y in 0..64 {
        for x in 0..64 {
            let (t, p) = floor_hit(&camera, x, y);
            if !(0.0..=1.0).contains(&p.x) || !(0.0..=1.0).contains(&p.y) {
                continue;
            }
            let b = h.element(h.locate(0, p)).shape().bounds();
            let d = (p.x - b.min.x)
                .min(b.max.x - p.x)
                .min(p.y - b.min.y)
                .min(b.max.y - p.y);
            let footprint = camera.pixel_footprint(t);
            if d < 0.45 * footprint {
                assert_eq!(image.get(x, y), red);
                lines += 1;
            } else if d > 0.55 * footprint {
                assert_ne!(image.get(x, y), red);
                clear += 1;
            }
        }
    }
    assert!(lines > 100 && clear > 1500, "{lines} {clear}");
    // The line x = 0.5 is unbroken: every image row over the floor has a red pixel where it crosses.
    for y in 5..59 {
        let (_, p) = floor_hit(&camera, 32, y);
        if (0.02..0.98).contains(&p.y) {
            assert!((28..36).any(|x| image.get(x, y) == red), "row {y}");
        }
    }
}

/// Header lines and the byte offset of the body of a PLY file.
fn ply_header(bytes: &[u8]) -> (Vec<String>, usize) {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("end_header")
        + 11;
    let text = std::str::from_utf8(&bytes[..end]).unwrap();
    (text.lines().map(str::to_string).collect(), end)
}

fn f32_at(bytes: &[u8], offset: usize) -> f32 {
    f32::from_le_bytes(bytes[offset..offset + 4].try_into().unwrap())
}

fn u32_at(bytes: &[u8], offset: usize) -> u32 {
    u32::from_le_bytes(bytes[offset..offset + 4].try_into().unwrap())
}

#[test]
fn shaded_mesh_covers_the_leaves_and_honours_t_vertices() {
    let (_, h) = floor_setup(false);
    let vr = VertexRadiosity::new(&h);
    let mesh = vr.mesh(&h);
    let area: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let p = t.map(|i| mesh.positions[i as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            assert!(n.z > 0.0, "triangles face the front");
            0.5 * n.length()
        })
        .sum();
    assert!((area - 1.0).abs() < 1e-12);
    // Watertight: every interior edge is used by exactly two triangles (no T-junctions), boundary edges once.
    let mut edges = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
            *edges.entry((a, b)).or_insert(0) += 1;
        }
    }
    for (&(a, b), &count) in &edges {
        let mid = (mesh.positions[a as usize] + mesh.positions[b as usize]) * 0.5;
        let on_border = mid.x.min(mid.y).min(1.0 - mid.x).min(1.0 - mid.y) < 1e-12;
        assert_eq!(count, if on_border { 1 } else { 2 }, "edge {a}-{b}");
    }
    // Vertex values are the renderer's interpolation at the vertices.
    for (p, v) in mesh.positions.iter().zip(&mesh.radiance) {
        let q = *p * (1.0 - 1e-12) + DVec3::splat(0.5e-12);
        let d = (vr.evaluate(&h, h.locate(0, q), q) - *v)
            .map(f64::abs)
            .max_channel();
        assert!(d < 1e-9);
    }
}

#[test]
fn ply_parses_back() {
    let (_, h) = floor_setup(false);
    let vr = VertexRadiosity::new(&h);
    let mesh = vr.mesh(&h);
    let path = temp_dir("ply").join("floor.ply");
    let tone = ToneMap {
        exposure: Exposure::Multiplier(0.3),
        curve: Curve::Linear,
    };
    write_ply(&path, &h, &vr, &tone).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let (header, body) = ply_header(&bytes);
    assert_eq!(header[0], "ply");
    assert_eq!(header[1], "format binary_little_endian 1.0");
    let count = |element: &str| {
        header
            .iter()
            .find_map(|l| l.strip_prefix(&format!("element {element} ")))
            .unwrap()
            .parse::<usize>()
            .unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    assert_eq!((nv, nf), (mesh.positions.len(), mesh.triangles.len()));
    let stride = 6 * 4 + 3 + 3 * 4;
    assert_eq!(bytes.len(), body + nv * stride + nf * 13);
    for i in 0..nv {
        let o = body + i * stride;
        let p = mesh.positions[i];
        assert_eq!(f32_at(&bytes, o), p.x as f32);
        assert_eq!(f32_at(&bytes, o + 8), p.z as f32);
        let linear = mesh.radiance[i];
        assert_eq!(f32_at(&bytes, o + 27), linear.r as f32);
        assert_eq!(f32_at(&bytes, o + 35), linear.b as f32);
        // Colour: exposure 0.3, clamp, sRGB.
        let c = radiosity::output::tonemap::rgb8((linear * 0.3).map(|x| x.min(1.0)));
        assert_eq!(&bytes[o + 24..o + 27], &c);
    }
    let faces = body + nv * stride;
    for (f, t) in mesh.triangles.iter().enumerate() {
        let o = faces + f * 13;
        assert_eq!(bytes[o], 3);
        for (k, &index) in t.iter().enumerate() {
            assert_eq!(u32_at(&bytes, o + 1 + 4 * k), index);
        }
    }
    let err = write_ply(&temp_dir("ply").join("no/such/dir.ply"), &h, &vr, &tone).unwrap_err();
    assert!(format!("{err:#}").contains("dir.ply"));
}

#[test]
fn glb_parses_back() {
    let (_, h) = floor_setup(false);
    let vr = VertexRadiosity::new(&h);
    let mesh = vr.mesh(&h);
    let tone = ToneMap {
        exposure: Exposure::Multiplier(0.2),
        curve: Curve::Reinhard,
    };
    let path = temp_dir("glb").join("floor.glb");
    write_glb(&path, &h, &vr, &tone).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(u32_at(&bytes, 4), 2);
    assert_eq!(u32_at(&bytes, 8) as usize, bytes.len());
    let json_len = u32_at(&bytes, 12) as usize;
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let gltf: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let bin_header = 20 + json_len;
    let bin_len = u32_at(&bytes, bin_header) as usize;
    assert_eq!(&bytes[bin_header + 4..bin_header + 8], b"BIN\0");
    assert_eq!(bin_len % 4, 0);
    assert_eq!(bin_header + 8 + bin_len, bytes.len());
    let bin = &bytes[bin_header + 8..];

    assert_eq!(gltf["asset"]["version"], "2.0");
    assert_eq!(gltf["extensionsUsed"][0], "KHR_materials_unlit");
    assert!(gltf["materials"][0]["extensions"]["KHR_materials_unlit"].is_object());
    let buffer_len = gltf["buffers"][0]["byteLength"].as_u64().unwrap() as usize;
    assert!(buffer_len <= bin_len && bin_len - buffer_len < 4);
    let primitive = &gltf["meshes"][0]["primitives"][0];
    let accessor = |name: &str| {
        let index = primitive["attributes"][name].as_u64().unwrap() as usize;
        gltf["accessors"][index].clone()
    };
    let n = mesh.positions.len() as u64;
    for name in ["POSITION", "NORMAL", "COLOR_0"] {
        assert_eq!(accessor(name)["count"].as_u64(), Some(n));
        assert_eq!(accessor(name)["type"], "VEC3");
        assert_eq!(accessor(name)["componentType"], 5126);
    }
    let indices = &gltf["accessors"][primitive["indices"].as_u64().unwrap() as usize];
    assert_eq!(
        indices["count"].as_u64(),
        Some(3 * mesh.triangles.len() as u64)
    );
    // Buffer views lie inside the buffer and match their accessors' sizes.
    let view = |accessor: &serde_json::Value| {
        let v = &gltf["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
        let offset = v["byteOffset"].as_u64().unwrap() as usize;
        let length = v["byteLength"].as_u64().unwrap() as usize;
        assert!(offset + length <= buffer_len);
        (offset, length)
    };
    let (pos_offset, pos_len) = view(&accessor("POSITION"));
    assert_eq!(pos_len, mesh.positions.len() * 12);
    let (col_offset, _) = view(&accessor("COLOR_0"));
    let (idx_offset, idx_len) = view(indices);
    assert_eq!(idx_len, mesh.triangles.len() * 12);
    let min = &accessor("POSITION")["min"];
    for i in 0..mesh.positions.len() {
        let p = mesh.positions[i];
        assert_eq!(f32_at(bin, pos_offset + 12 * i + 4), p.y as f32);
        assert!(f64::from(f32_at(bin, pos_offset + 12 * i)) >= min[0].as_f64().unwrap());
        // COLOR_0: exposure and Reinhard, no gamma.
        let expected = mesh.radiance[i].r * 0.2 / (1.0 + mesh.radiance[i].r * 0.2);
        assert_eq!(f32_at(bin, col_offset + 12 * i), expected as f32);
    }
    for (f, t) in mesh.triangles.iter().enumerate() {
        assert_eq!(u32_at(bin, idx_offset + 12 * f + 8), t[2]);
    }
}

/// An axis-aligned quad facing `towards` (vertex order fixed so its normal points that way).
fn quad_facing(corners: [DVec3; 4], towards: DVec3) -> Shape {
    let q = Shape::Quad(corners);
    if q.normal().dot(towards) < 0.0 {
        q.flipped()
    } else {
        q
    }
}

/// Fraction of `light` visible from `p`, by a 4 x 4 grid of points on it.
fn light_visibility(vis: &dyn Visibility, p: DVec3, light: &Shape) -> f64 {
    let mut seen = 0;
    for i in 0..4 {
        for j in 0..4 {
            let q = light.point_at(DVec2::new((i as f64 + 0.5) / 4.0, (j as f64 + 0.5) / 4.0));
            seen += usize::from(!vis.segment_occluded(p, q));
        }
    }
    seen as f64 / 16.0
}

/// A box lit by a ceiling light with a block casting a shadow: direct light plus a constant ambient term,
/// refined where the light is partly hidden. Written as PNGs (flat + mesh, smooth, smooth + mesh) for a
/// person to look at; the test checks what can be checked automatically.
#[test]
fn lit_box_renders_with_mesh_overlay() {
    const AMBIENT: f64 = 0.15;
    let v = DVec3::new;
    let mut polygons = Vec::new();
    let centre = v(0.5, 0.5, 0.5);
    let face = |c: [DVec3; 4], towards: DVec3| quad_facing(c, towards);
    // Walls facing into the box (open at z = 1): floor, ceiling, back, left (red), right (green).
    polygons.push((
        face(
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)],
            centre - v(0.5, 0., 0.5),
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(0., 1., 0.), v(1., 1., 0.), v(1., 1., 1.), v(0., 1., 1.)],
            -DVec3::Y,
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
            DVec3::Z,
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(0., 0., 0.), v(0., 1., 0.), v(0., 1., 1.), v(0., 0., 1.)],
            DVec3::X,
        ),
        1,
        false,
    ));
    polygons.push((
        face(
            [v(1., 0., 0.), v(1., 1., 0.), v(1., 1., 1.), v(1., 0., 1.)],
            -DVec3::X,
        ),
        2,
        false,
    ));
    // Light just below the ceiling, facing down.
    let light = face(
        [
            v(0.35, 0.99, 0.35),
            v(0.65, 0.99, 0.35),
            v(0.65, 0.99, 0.65),
            v(0.35, 0.99, 0.65),
        ],
        -DVec3::Y,
    );
    polygons.push((light, 3, false));
    // A block on the floor: top and four sides.
    let (x0, x1, y1, z0, z1) = (0.55, 0.8, 0.3, 0.2, 0.45);
    polygons.push((
        face(
            [v(x0, y1, z0), v(x1, y1, z0), v(x1, y1, z1), v(x0, y1, z1)],
            DVec3::Y,
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(x0, 0., z1), v(x1, 0., z1), v(x1, y1, z1), v(x0, y1, z1)],
            DVec3::Z,
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(x0, 0., z0), v(x1, 0., z0), v(x1, y1, z0), v(x0, y1, z0)],
            -DVec3::Z,
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(x0, 0., z0), v(x0, y1, z0), v(x0, y1, z1), v(x0, 0., z1)],
            -DVec3::X,
        ),
        0,
        false,
    ));
    polygons.push((
        face(
            [v(x1, 0., z0), v(x1, y1, z0), v(x1, y1, z1), v(x1, 0., z1)],
            DVec3::X,
        ),
        0,
        false,
    ));
    let materials = vec![
        Material::diffuse("white", Rgb::splat(0.75)),
        Material::diffuse("red", Rgb::new(0.63, 0.06, 0.04)),
        Material::diffuse("green", Rgb::new(0.15, 0.48, 0.09)),
        Material::emitter("light", Rgb::splat(0.78), Rgb::splat(10.0)),
    ];
    let s = scene(polygons, materials);
    let vis = visibility(&s);
    let mut h = Hierarchy::new(&s, radiosity::bases::BasisKind::Constant);
    let light_patch = 5;

    // Uniform level 2, then split partly shadowed leaves down to level 6.
    for _ in 0..2 {
        for leaf in h.leaves() {
            h.subdivide(leaf);
        }
    }
    for _ in 2..6 {
        for leaf in h.leaves() {
            let e = h.element(leaf);
            if e.patch() == light_patch {
                continue;
            }
            let shape = *e.shape();
            let n = h.patch_of(leaf).normal;
            let c = shape.centroid();
            let probes: Vec<f64> = shape
                .vertices()
                .iter()
                .chain([&c])
                .map(|p| light_visibility(&vis, *p * 0.98 + c * 0.02 + n * 1e-6, &light))
                .collect();
            if probes.iter().any(|&f| f != probes[0]) {
                h.subdivide(leaf);
            }
        }
    }
    for leaf in h.leaves() {
        let e = h.element(leaf);
        let patch = h.patch_of(leaf);
        let c = e.shape().centroid();
        let direct = point_to_polygon(c, patch.normal, &light)
            * light_visibility(&vis, c + patch.normal * 1e-6, &light);
        let radiance =
            patch.emission + patch.reflectance * (Rgb::splat(10.0) * direct + Rgb::splat(AMBIENT));
        h.radiance_mut(leaf)[0] = radiance;
    }
    let vr = VertexRadiosity::new(&h);
    assert!(vr.fanned_leaf_count() > 10);

    let spec = CameraSpec {
        eye: v(0.5, 0.5, 2.4),
        look_at: v(0.5, 0.5, 0.5),
        up: DVec3::Y,
        fov_degrees: 40.0,
    };
    let camera = Camera::new(&spec, 320, 320);
    let dir = temp_dir("visual");
    // The light covers a few percent of the view, so the automatic exposure would follow it: fix it.
    let tone = ToneMap {
        exposure: Exposure::Multiplier(1.2),
        curve: Curve::Filmic,
    };
    let mut images: Vec<(&str, Image)> = Vec::new();
    // A close-up of the block's shadow, where the mesh is finest and T-vertices abound.
    let closeup = Camera::new(
        &CameraSpec {
            eye: v(0.45, 0.55, 0.95),
            look_at: v(0.7, 0.0, 0.5),
            up: DVec3::Y,
            fov_degrees: 45.0,
        },
        320,
        320,
    );
    for (name, shading, mesh, camera) in [
        ("box_flat_mesh", Shading::Flat, true, &camera),
        ("box_smooth", Shading::Smooth, false, &camera),
        ("box_smooth_mesh", Shading::Smooth, true, &camera),
        ("closeup_smooth", Shading::Smooth, false, &closeup),
        ("closeup_smooth_mesh", Shading::Smooth, true, &closeup),
    ] {
        let options = RenderOptions {
            shading,
            mesh,
            ..Default::default()
        };
        let image = render_with(&h, &vis, camera, &options, Some(&vr));
        write_png(&dir.join(format!("{name}.png")), &image, &tone).unwrap();
        images.push((name, image));
    }
    eprintln!("lit box images in {}", dir.display());
    write_glb(&dir.join("box.glb"), &h, &vr, &tone).unwrap();
    write_ply(&dir.join("box.ply"), &h, &vr, &tone).unwrap();

    let smooth = &images[1].1;
    // The light (seen from below at the top centre) is the brightest thing; the left wall is red, the
    // right green; the flat + mesh image has black lines.
    let max = smooth
        .pixels
        .iter()
        .map(|p| p.luminance())
        .fold(0.0, f64::max);
    assert!((max - (10.0 + 0.78 * AMBIENT)).abs() < 1e-9, "{max}");
    let left = smooth.get(60, 160);
    let right = smooth.get(260, 160);
    assert!(
        left.r > 3.0 * left.g && right.g > 2.0 * right.r,
        "{left:?} {right:?}"
    );
    let black = images[0].1.pixels.iter().filter(|p| p.is_black()).count();
    assert!(black > 3000, "{black}");
    let srgb = to_srgb8(smooth, &tone);
    assert_eq!(srgb.dimensions(), (320, 320));
}

/// Without a camera in the file, RenderPark's rooms are viewed from inside (their outer faces are
/// unlit: from outside the image is black) and its lone fixture from outside. office2 and the classroom
/// have window frames and sills up to 7.5 cm outside their walls, which the enclosure test must allow.
#[test]
fn renderpark_rooms_are_viewed_from_inside_and_the_fixture_from_outside() {
    use radiosity::output::camera::Camera;
    use radiosity::scene::{self, LoadOptions};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/renderpark");
    for (file, room) in [
        ("cube.mgf", true),
        ("corridor.mgf", true),
        ("office2/office2.mgf", true),
        ("office3/office.mgf", true),
        ("salon/classroom.mgf", true),
        ("examp1.mgf", false),
    ] {
        let scene = scene::load(&dir.join(file), &LoadOptions::default()).expect(file);
        let bounds = scene.bounds();
        let eye = Camera::auto_view(&scene, 60.0).eye;
        let inside = (0..3).all(|a| eye[a] > bounds.min[a] && eye[a] < bounds.max[a]);
        assert_eq!(inside, room, "{file}: eye {eye} in {bounds:?}");
    }
}

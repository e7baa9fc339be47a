//! Test scenes with known answers: the analytic form factor configurations, the closed "furnace" box, and
//! the shadow-group scene of Sillion & Drettakis (Figures 1 and 9) for the feature-based error metric;
//! and a hall of boxes of any size ([`BoxHall`]) to measure how solves scale.

use super::{CameraSpec, Material, Object, Polygon, Scene};
use crate::color::Rgb;
use crate::geometry::{DVec3, Shape};

fn quad(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> Shape {
    Shape::Quad([a, b, c, d])
}

fn scene_of(faces: Vec<(Shape, usize, &str)>, materials: Vec<Material>) -> Scene {
    let mut scene = Scene {
        materials,
        ..Default::default()
    };
    for (shape, material, name) in faces {
        let object = scene.objects.len();
        scene.objects.push(Object {
            name: name.to_string(),
        });
        scene.polygons.push(Polygon {
            shape,
            material,
            object,
            two_sided: false,
            under_contact: false,
        });
    }
    scene
}

/// Two coaxial parallel squares of side `size` at `distance`: the lower one (z = 0, facing +z) reflects
/// with `reflectance`, the upper one (facing -z) emits radiance `emission` and reflects nothing. The lower
/// square's radiance is then ρ F E with F the analytic form factor.
pub fn parallel_plates(size: f64, distance: f64, reflectance: f64, emission: f64) -> Scene {
    let s = size;
    let receiver = quad(
        DVec3::ZERO,
        DVec3::new(s, 0.0, 0.0),
        DVec3::new(s, s, 0.0),
        DVec3::new(0.0, s, 0.0),
    );
    let h = distance;
    let emitter = quad(
        DVec3::new(0.0, 0.0, h),
        DVec3::new(0.0, s, h),
        DVec3::new(s, s, h),
        DVec3::new(s, 0.0, h),
    );
    scene_of(
        vec![(receiver, 0, "receiver"), (emitter, 1, "emitter")],
        vec![
            Material::diffuse("receiver", Rgb::splat(reflectance)),
            Material::emitter("emitter", Rgb::BLACK, Rgb::splat(emission)),
        ],
    )
}

/// Two squares of side `size` at a right angle sharing an edge (the x axis): the horizontal one (facing
/// +z) reflects, the vertical one (facing +y) emits.
pub fn perpendicular_plates(size: f64, reflectance: f64, emission: f64) -> Scene {
    let s = size;
    let receiver = quad(
        DVec3::ZERO,
        DVec3::new(s, 0.0, 0.0),
        DVec3::new(s, s, 0.0),
        DVec3::new(0.0, s, 0.0),
    );
    let emitter = quad(
        DVec3::ZERO,
        DVec3::new(0.0, 0.0, s),
        DVec3::new(s, 0.0, s),
        DVec3::new(s, 0.0, 0.0),
    );
    scene_of(
        vec![(receiver, 0, "receiver"), (emitter, 1, "emitter")],
        vec![
            Material::diffuse("receiver", Rgb::splat(reflectance)),
            Material::emitter("emitter", Rgb::BLACK, Rgb::splat(emission)),
        ],
    )
}

/// The six inward-facing faces of an axis-aligned box [0, size]^3, in the order -x, +x, -y, +y, -z, +z.
pub fn box_faces(size: DVec3) -> [Shape; 6] {
    let (x, y, z) = (size.x, size.y, size.z);
    let p = |a: f64, b: f64, c: f64| DVec3::new(a, b, c);
    [
        quad(p(0., 0., 0.), p(0., y, 0.), p(0., y, z), p(0., 0., z)),
        quad(p(x, 0., 0.), p(x, 0., z), p(x, y, z), p(x, y, 0.)),
        quad(p(0., 0., 0.), p(0., 0., z), p(x, 0., z), p(x, 0., 0.)),
        quad(p(0., y, 0.), p(x, y, 0.), p(x, y, z), p(0., y, z)),
        quad(p(0., 0., 0.), p(x, 0., 0.), p(x, y, 0.), p(0., y, 0.)),
        quad(p(0., 0., z), p(0., y, z), p(x, y, z), p(x, 0., z)),
    ]
}

/// The six outward-facing faces of the box `corner + [0, size]`, in the order of [`box_faces`].
fn outward_box_faces(corner: DVec3, size: DVec3) -> [Shape; 6] {
    box_faces(size).map(|f| {
        let v = f.vertices();
        quad(v[3] + corner, v[2] + corner, v[1] + corner, v[0] + corner)
    })
}

/// The white furnace: a closed box whose faces all reflect ρ and emit E; every point converges to
/// E / (1 - ρ).
pub fn furnace(size: DVec3, reflectance: f64, emission: f64) -> Scene {
    let faces = box_faces(size)
        .into_iter()
        .map(|f| (f, 0, "wall"))
        .collect();
    scene_of(
        faces,
        vec![Material::emitter(
            "furnace",
            Rgb::splat(reflectance),
            Rgb::splat(emission),
        )],
    )
}

/// A closed box of reflectance ρ whose ceiling (+y face) alone emits: all emitted power must be absorbed.
pub fn lit_box(size: DVec3, reflectance: Rgb, emission: f64) -> Scene {
    let faces = box_faces(size)
        .into_iter()
        .enumerate()
        .map(|(k, f)| (f, usize::from(k == 3), "wall"))
        .collect();
    scene_of(
        faces,
        vec![
            Material::diffuse("wall", reflectance),
            Material::emitter("ceiling", reflectance, Rgb::splat(emission)),
        ],
    )
}

/// The scene of Sillion & Drettakis, Figures 1 and 9 (§2.1, §5): a wall lit by a small square source
/// through four groups of cubes, each group made of cubes of one size. Every group covers the same square
/// footprint with the same fraction of cube (its cubes sit on a regular grid of pitch ≈ `spacing` × size),
/// so the groups block the same average light — the configuration in which the four L² errors of an
/// averaged approximation are alike while the shadow sizes differ (§2.1 and Appendix A).
///
/// Frame: the wall lies in the plane z = 0 facing +z, centred on the origin; the groups lie side by side
/// along x, smallest cubes first (left, at −x), their centres at height z = `cube_distance`; the source
/// faces the wall at z = `light_distance` above the origin. The first [`wall_tiles`](Self::wall_tiles)
/// polygons are the wall, the next one is the source, then come the cubes group by group (six outward
/// faces each; one object per group), then the floor if any.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowGroups {
    /// Edge length of the cubes of each group, left to right.
    pub cube_sizes: Vec<f64>,
    /// Grid pitch over cube size: 2 leaves a gap of one cube between neighbours (a quarter covered).
    pub spacing: f64,
    /// Side of the square footprint of every group.
    pub group_width: f64,
    /// Gap between the footprints of neighbouring groups.
    pub group_gap: f64,
    /// Distance of the cube centres from the wall.
    pub cube_distance: f64,
    /// Distance of the source from the wall.
    pub light_distance: f64,
    /// Side of the square source.
    pub light_size: f64,
    /// Emitted radiance of the source, W/(m² sr).
    pub emission: f64,
    /// Reflectance of the wall (and floor).
    pub wall_reflectance: f64,
    /// Reflectance of the cubes.
    pub cube_reflectance: f64,
    /// Adds a floor under the wall, from the wall to below the source, facing up.
    pub floor: bool,
}

impl Default for ShadowGroups {
    /// Four groups of 16×16, 8×8, 4×4 and 2×2 cubes (sizes 0.03 to 0.24, a factor 2 apart, like the four
    /// clusters of Figure 1), 0.4 from the wall, the source 3 away: shadows of about 0.035 to 0.29 with
    /// penumbrae of 0.008, and a wall radiance of order 1.
    fn default() -> Self {
        ShadowGroups {
            cube_sizes: vec![0.03, 0.06, 0.12, 0.24],
            spacing: 2.0,
            group_width: 0.96,
            group_gap: 0.3,
            cube_distance: 0.4,
            light_distance: 3.0,
            light_size: 0.05,
            emission: 8000.0,
            wall_reflectance: 0.5,
            cube_reflectance: 0.5,
            floor: false,
        }
    }
}

impl ShadowGroups {
    /// Checks that the layout is a valid scene: positive sizes, cubes between wall and source.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("spacing", self.spacing),
            ("group width", self.group_width),
            ("cube distance", self.cube_distance),
            ("light distance", self.light_distance),
            ("light size", self.light_size),
        ];
        for (what, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{what} must be positive, not {v}"));
            }
        }
        if self.cube_sizes.is_empty() {
            return Err("at least one cube size is needed".into());
        }
        if !(self.group_gap.is_finite() && self.group_gap >= 0.0) {
            return Err(format!("group gap must be >= 0, not {}", self.group_gap));
        }
        if self.spacing < 1.0 {
            return Err(format!(
                "spacing {} < 1 would overlap the cubes",
                self.spacing
            ));
        }
        for &s in &self.cube_sizes {
            if !(s.is_finite() && s > 0.0 && s <= self.group_width) {
                return Err(format!(
                    "cube size {s} must be positive and at most the group width {}",
                    self.group_width
                ));
            }
            if self.cube_distance - s / 2.0 <= 0.0
                || self.cube_distance + s / 2.0 >= self.light_distance
            {
                return Err(format!(
                    "cubes of size {s} at distance {} must lie between the wall and the source at {}",
                    self.cube_distance, self.light_distance
                ));
            }
        }
        for (what, v) in [
            ("emission", self.emission),
            ("wall reflectance", self.wall_reflectance),
            ("cube reflectance", self.cube_reflectance),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{what} must be >= 0, not {v}"));
            }
        }
        if self.wall_reflectance >= 1.0 || self.cube_reflectance >= 1.0 {
            return Err("reflectances must be below 1".into());
        }
        Ok(())
    }

    /// Cubes per side of group `k`: as many as fit at pitch `spacing` × size (at least one).
    pub fn cubes_per_side(&self, k: usize) -> usize {
        ((self.group_width / (self.spacing * self.cube_sizes[k]) + 1e-9).floor() as usize).max(1)
    }

    /// Centre (x) of the footprint of group `k`; the groups are centred on the origin.
    pub fn group_centre(&self, k: usize) -> f64 {
        let n = self.cube_sizes.len() as f64;
        (k as f64 - (n - 1.0) / 2.0) * (self.group_width + self.group_gap)
    }

    /// Central projection from the source centre onto the wall of a point at height z: the factor that
    /// scales its (x, y).
    fn magnification(&self, z: f64) -> f64 {
        self.light_distance / (self.light_distance - z)
    }

    /// The rectangle of the wall, [x0, x1] × [y0, y1], that holds the shadow (umbra and penumbra) of
    /// group `k`: its footprint projected from the source centre, grown by the penumbra width.
    pub fn shadow_region(&self, k: usize) -> [f64; 4] {
        let s = self.cube_sizes[k];
        let top = self.cube_distance + s / 2.0;
        let m = self.magnification(top);
        let penumbra = self.light_size * top / (self.light_distance - top);
        let c = self.group_centre(k);
        let half = self.group_width / 2.0;
        [
            (c - half) * m - penumbra,
            (c + half) * m + penumbra,
            -half * m - penumbra,
            half * m + penumbra,
        ]
    }

    /// Half extents (x, y) of the wall: every shadow region with a margin of a quarter group width.
    pub fn wall_half_extent(&self) -> (f64, f64) {
        let margin = 0.25 * self.group_width;
        let (mut hx, mut hy) = (0.0f64, 0.0f64);
        for k in 0..self.cube_sizes.len() {
            let [x0, x1, _, y1] = self.shadow_region(k);
            hx = hx.max(x0.abs()).max(x1.abs());
            hy = hy.max(y1);
        }
        (hx + margin, hy + margin)
    }

    /// The wall is made of this many tiles side by side along x, each about square, so that the element
    /// quadtrees refine it into square elements.
    pub fn wall_tiles(&self) -> usize {
        let (hx, hy) = self.wall_half_extent();
        ((hx / hy).round() as usize).max(1)
    }

    /// The scene (call [`validate`](Self::validate) first on user input).
    pub fn scene(&self) -> Scene {
        let p = DVec3::new;
        let (hx, hy) = self.wall_half_extent();
        let d = self.light_distance;
        let l = self.light_size / 2.0;
        let tiles = self.wall_tiles();
        let w = 2.0 * hx / tiles as f64;
        let mut faces: Vec<_> = (0..tiles)
            .map(|i| {
                let (x0, x1) = (-hx + i as f64 * w, -hx + (i + 1) as f64 * w);
                let tile = quad(p(x0, -hy, 0.), p(x1, -hy, 0.), p(x1, hy, 0.), p(x0, hy, 0.));
                (tile, 0, "wall".to_string())
            })
            .collect();
        faces.push((
            quad(p(-l, -l, d), p(-l, l, d), p(l, l, d), p(l, -l, d)),
            1,
            "light".to_string(),
        ));
        for (k, &s) in self.cube_sizes.iter().enumerate() {
            let n = self.cubes_per_side(k);
            let pitch = self.group_width / n as f64;
            let x0 = self.group_centre(k) - self.group_width / 2.0;
            let y0 = -self.group_width / 2.0;
            let name = format!("group{}-cubes-{s}", k + 1);
            for i in 0..n {
                for j in 0..n {
                    let centre = p(
                        x0 + (i as f64 + 0.5) * pitch,
                        y0 + (j as f64 + 0.5) * pitch,
                        self.cube_distance,
                    );
                    let corner = centre - DVec3::splat(s / 2.0);
                    for outward in outward_box_faces(corner, DVec3::splat(s)) {
                        faces.push((outward, 2, name.clone()));
                    }
                }
            }
        }
        if self.floor {
            faces.push((
                quad(
                    p(-hx, -hy, 0.),
                    p(-hx, -hy, d),
                    p(hx, -hy, d),
                    p(hx, -hy, 0.),
                ),
                0,
                "floor".to_string(),
            ));
        }
        let mut scene = Scene {
            materials: vec![
                Material::diffuse("wall", Rgb::splat(self.wall_reflectance)),
                Material::emitter("light", Rgb::BLACK, Rgb::splat(self.emission)),
                Material::diffuse("cubes", Rgb::splat(self.cube_reflectance)),
            ],
            // An oblique view from above and in front, like the left image of Figure 9.
            camera: Some(CameraSpec {
                eye: p(0.6 * hx, 2.2 * hy, 1.3 * d),
                look_at: p(0.0, 0.0, 0.5 * self.cube_distance),
                up: DVec3::Y,
                fov_degrees: 50.0,
            }),
            ..Default::default()
        };
        for (shape, material, name) in faces {
            let object = match scene.objects.iter().position(|o| o.name == name) {
                Some(i) => i,
                None => {
                    scene.objects.push(Object { name });
                    scene.objects.len() - 1
                }
            };
            scene.polygons.push(Polygon {
                shape,
                material,
                object,
                two_sided: false,
                under_contact: false,
            });
        }
        scene
    }
}

/// A hall of boxes that grows to any polygon count, for measuring how solves scale: a closed room
/// (one-sided faces pointing in) whose floor carries an `m × m` grid of boxes (five outward faces each,
/// no bottom) of pseudo-random heights, lit by one ceiling panel per `4 × 4` boxes. The density of
/// boxes, lights and area per box is the same at every size, so the work per polygon of a solver that
/// scales is too.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxHall {
    /// Boxes per side.
    pub boxes_per_side: usize,
}

/// Polygons of a [`BoxHall`] per box.
const FACES_PER_BOX: usize = 5;

impl BoxHall {
    /// Grid pitch of the boxes, and the room's height.
    const PITCH: f64 = 1.0;
    const HEIGHT: f64 = 3.0;

    /// The hall with about `polygons` polygons (at least one box).
    pub fn with_polygons(polygons: usize) -> Self {
        let boxes = polygons as f64 / (FACES_PER_BOX as f64 + 1.0 / 16.0);
        BoxHall {
            boxes_per_side: (boxes.sqrt().round() as usize).max(1),
        }
    }

    /// Number of ceiling panels per side.
    fn lights_per_side(&self) -> usize {
        self.boxes_per_side.div_ceil(4)
    }

    /// Polygons of the scene: room, lights and boxes.
    pub fn polygon_count(&self) -> usize {
        6 + self.lights_per_side().pow(2) + FACES_PER_BOX * self.boxes_per_side.pow(2)
    }

    pub fn scene(&self) -> Scene {
        let m = self.boxes_per_side;
        let side = m as f64 * Self::PITCH;
        let h = Self::HEIGHT;
        let p = DVec3::new;
        let mut faces: Vec<(Shape, usize)> = box_faces(p(side, side, h))
            .into_iter()
            .map(|f| (f, 0))
            .collect();
        let lights = self.lights_per_side();
        let cell = side / lights as f64;
        let half = 0.15 * cell;
        for i in 0..lights {
            for j in 0..lights {
                let (x, y) = ((i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell);
                let z = 0.99 * h;
                faces.push((
                    quad(
                        p(x - half, y - half, z),
                        p(x - half, y + half, z),
                        p(x + half, y + half, z),
                        p(x + half, y - half, z),
                    ),
                    1,
                ));
            }
        }
        for i in 0..m {
            for j in 0..m {
                let key = crate::random::splitmix64((i * m + j) as u64);
                let height = 0.3 + 0.6 * crate::random::unit_interval(key);
                let corner = p(
                    (i as f64 + 0.25) * Self::PITCH,
                    (j as f64 + 0.25) * Self::PITCH,
                    0.0,
                );
                let size = p(0.5 * Self::PITCH, 0.5 * Self::PITCH, height);
                // Without the bottom (-z), which touches the floor.
                for (k, outward) in outward_box_faces(corner, size).into_iter().enumerate() {
                    if k != 4 {
                        faces.push((outward, 2));
                    }
                }
            }
        }
        let mut scene = scene_of(
            Vec::new(),
            vec![
                Material::diffuse("walls", Rgb::splat(0.6)),
                Material::emitter("light", Rgb::BLACK, Rgb::splat(10.0)),
                Material::diffuse("boxes", Rgb::new(0.6, 0.4, 0.3)),
            ],
        );
        scene.objects = ["room", "lights", "boxes"]
            .iter()
            .map(|name| Object {
                name: name.to_string(),
            })
            .collect();
        scene.polygons = faces
            .into_iter()
            .map(|(shape, material)| Polygon {
                shape,
                material,
                object: material,
                two_sided: false,
                under_contact: false,
            })
            .collect();
        scene.camera = Some(CameraSpec {
            eye: p(0.02 * side, 0.02 * side, 0.9 * h),
            look_at: p(0.5 * side, 0.5 * side, 0.0),
            up: DVec3::Z,
            fov_degrees: 60.0,
        });
        scene
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_faces_point_inward() {
        let size = DVec3::new(1.0, 2.0, 3.0);
        let centre = size * 0.5;
        for f in box_faces(size) {
            assert!(f.normal().dot(centre - f.centroid()) > 0.0);
            assert!(f.area() > 0.0);
        }
    }

    #[test]
    fn shadow_groups_layout() {
        let g = ShadowGroups::default();
        g.validate().unwrap();
        let scene = g.scene();
        let counts: Vec<usize> = (0..4).map(|k| g.cubes_per_side(k)).collect();
        assert_eq!(counts, [16, 8, 4, 2]);
        let t = g.wall_tiles();
        assert_eq!(t, 4);
        assert_eq!(scene.polygons.len(), t + 1 + 6 * (256 + 64 + 16 + 4));
        assert_eq!(scene.objects.len(), 6);
        let (hx, hy) = g.wall_half_extent();
        let wall: f64 = scene.polygons[..t].iter().map(|p| p.shape.area()).sum();
        assert!((wall - 4.0 * hx * hy).abs() < 1e-12);
        for p in &scene.polygons[..t] {
            assert_eq!(p.shape.normal(), DVec3::Z);
        }
        assert_eq!(scene.polygons[t].shape.normal(), -DVec3::Z);
        let light = scene.polygons[t].shape.centroid();
        // Cube faces point away from their cube, and every cube lies between wall and source.
        for p in &scene.polygons[t + 1..] {
            let c = p.shape.centroid();
            assert!(c.z > 0.0 && c.z < light.z);
            let cube_size = p.shape.area().sqrt();
            let cube_centre = c - p.shape.normal() * (cube_size / 2.0);
            assert!((cube_centre.z - g.cube_distance).abs() < 1e-12);
        }
        // Every group blocks the same fraction of its footprint.
        for k in 0..4 {
            let n = g.cubes_per_side(k) as f64;
            let cover = (n * g.cube_sizes[k] / g.group_width).powi(2);
            assert!((cover - 0.25).abs() < 1e-12);
        }
        // Shadow regions are disjoint and on the wall.
        for k in 0..4 {
            let [x0, x1, y0, y1] = g.shadow_region(k);
            assert!(x0 > -hx && x1 < hx && y0 > -hy && y1 < hy);
            if k > 0 {
                assert!(x0 > g.shadow_region(k - 1)[1]);
            }
        }
        let with_floor = ShadowGroups {
            floor: true,
            ..g.clone()
        };
        let floor = with_floor.scene().polygons.last().unwrap().shape;
        assert_eq!(floor.normal(), DVec3::Y);
        assert!(ShadowGroups {
            cube_distance: 3.5,
            ..g
        }
        .validate()
        .is_err());
    }

    #[test]
    fn box_hall_has_the_polygons_it_counts_and_is_closed() {
        let hall = BoxHall::with_polygons(10_000);
        let scene = hall.scene();
        assert_eq!(scene.polygons.len(), hall.polygon_count());
        assert!((scene.polygons.len() as f64 / 10_000.0 - 1.0).abs() < 0.05);
        // Every box face points away from its box, every room face into the room.
        let side = hall.boxes_per_side as f64 * BoxHall::PITCH;
        let centre = DVec3::new(0.5 * side, 0.5 * side, 0.5 * BoxHall::HEIGHT);
        for polygon in &scene.polygons[..6] {
            let s = polygon.shape;
            assert!(s.normal().dot(centre - s.centroid()) > 0.0);
        }
        for polygon in scene.polygons.iter().filter(|p| p.material == 2) {
            let s = polygon.shape;
            let cell = (s.centroid() / BoxHall::PITCH).floor() + DVec3::new(0.5, 0.5, 0.0);
            let box_base = DVec3::new(cell.x, cell.y, 0.0) * BoxHall::PITCH;
            assert!(s.normal().dot(s.centroid() - box_base) > 0.0);
        }
    }
}

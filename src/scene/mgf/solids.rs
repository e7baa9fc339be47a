//! Tessellation of the MGF solids (`sph`, `cyl`, `cone`, `ring`, `torus`, `prism`) into polygons in the
//! solid's own coordinates (the caller transforms them).
//!
//! Quality: `segments` is the number of segments per full circle (`LoadOptions::tessellation`). A
//! cylinder or cone becomes `segments` quads, a ring `segments` quads (triangles when it is a full disc),
//! a sphere `segments / 2` latitude bands of `segments` quads (triangles at the poles) and a torus
//! `segments × segments` quads. The default 16 (4 per quarter circle) is what RenderPark's MGF library
//! used; the relative area lost by an inscribed polygon is about (2π/segments)²/6, 2.6% at 16 and 0.16%
//! at 64. All quads are planar (isosceles trapezoids) and face outward; negative radii turn the normals
//! inward, as the MGF specification says.

use glam::DVec3;

/// A polygon in the solid's coordinates, counter-clockwise seen from its front.
pub type Loop = Vec<DVec3>;

/// Unit vectors u, v with (u, v, axis) right-handed.
fn frame(axis: DVec3) -> (DVec3, DVec3, DVec3) {
    let w = axis.normalize();
    let (u, v) = w.any_orthonormal_pair();
    (u, v, w)
}

fn circle(center: DVec3, u: DVec3, v: DVec3, radius: f64, segments: usize) -> Vec<DVec3> {
    (0..segments)
        .map(|j| {
            let phi = std::f64::consts::TAU * j as f64 / segments as f64;
            center + radius * (phi.cos() * u + phi.sin() * v)
        })
        .collect()
}

fn oriented(mut l: Loop, inward: bool) -> Loop {
    if inward {
        l.reverse();
    }
    l
}

/// `cone v1 r1 v2 r2`: open truncated cone; `cyl` is a cone with equal radii.
pub fn cone(p1: DVec3, r1: f64, p2: DVec3, r2: f64, segments: usize) -> Result<Vec<Loop>, String> {
    if r1 == 0.0 && r2 == 0.0 {
        return Err("cone radii are both zero".into());
    }
    if r1 * r2 < 0.0 {
        return Err("cone radii have different signs".into());
    }
    let axis = p2 - p1;
    if axis.length() == 0.0 {
        return Err("cone end points coincide (use ring)".into());
    }
    let inward = r1 < 0.0 || r2 < 0.0;
    let (u, v, _) = frame(axis);
    let a = circle(p1, u, v, r1.abs(), segments);
    let b = circle(p2, u, v, r2.abs(), segments);
    Ok((0..segments)
        .map(|j| {
            let k = (j + 1) % segments;
            // Tangent (around the axis) then along the axis: the normal points away from the axis.
            oriented(vec![a[j], a[k], b[k], b[j]], inward)
        })
        .collect())
}

/// `ring vc rmin rmax`: flat annulus (a disc when rmin = 0) facing the vertex normal.
pub fn ring(
    center: DVec3,
    normal: DVec3,
    rmin: f64,
    rmax: f64,
    segments: usize,
) -> Result<Vec<Loop>, String> {
    if normal.length() == 0.0 {
        return Err("ring centre vertex has no normal".into());
    }
    if !(rmin >= 0.0 && rmax > rmin) {
        return Err(format!(
            "ring radii must satisfy 0 <= rmin < rmax (got {rmin}, {rmax})"
        ));
    }
    let (u, v, _) = frame(normal);
    let outer = circle(center, u, v, rmax, segments);
    let inner = circle(center, u, v, rmin, segments);
    Ok((0..segments)
        .map(|j| {
            let k = (j + 1) % segments;
            if rmin == 0.0 {
                vec![center, outer[j], outer[k]]
            } else {
                vec![inner[j], outer[j], outer[k], inner[k]]
            }
        })
        .collect())
}

/// `sph vc r`: sphere; a negative radius faces inward.
pub fn sphere(center: DVec3, radius: f64, segments: usize) -> Result<Vec<Loop>, String> {
    if radius == 0.0 {
        return Err("sphere radius is zero".into());
    }
    let r = radius.abs();
    let bands = (segments / 2).max(2);
    let (u, v, w) = (DVec3::X, DVec3::Y, DVec3::Z);
    // Latitude rings from the north pole (theta = 0) to the south pole (theta = pi).
    let ring_at = |i: usize| {
        let theta = std::f64::consts::PI * i as f64 / bands as f64;
        circle(
            center + r * theta.cos() * w,
            u,
            v,
            r * theta.sin(),
            segments,
        )
    };
    let mut loops = Vec::with_capacity(bands * segments);
    let mut upper = ring_at(0);
    for i in 1..=bands {
        let lower = ring_at(i);
        for j in 0..segments {
            let k = (j + 1) % segments;
            // Down the meridian, then around the axis: (-w) × v = u points outward at phi = 0.
            let quad = vec![upper[j], lower[j], lower[k], upper[k]];
            let quad = if i == 1 {
                vec![upper[j], lower[j], lower[k]]
            } else if i == bands {
                vec![upper[j], lower[j], upper[k]]
            } else {
                quad
            };
            loops.push(oriented(quad, radius < 0.0));
        }
        upper = lower;
    }
    Ok(loops)
}

/// `torus vc rmin rmax`: torus around the vertex normal with inner and outer radii; negative radii face
/// inward.
pub fn torus(
    center: DVec3,
    normal: DVec3,
    rmin: f64,
    rmax: f64,
    segments: usize,
) -> Result<Vec<Loop>, String> {
    if normal.length() == 0.0 {
        return Err("torus centre vertex has no normal".into());
    }
    let inward = rmax < 0.0;
    if (rmin != 0.0 && (rmin < 0.0) != inward) || rmax.abs() <= rmin.abs() {
        return Err(format!(
            "torus radii must satisfy 0 <= |rmin| < |rmax| with equal signs (got {rmin}, {rmax})"
        ));
    }
    let (rmin, rmax) = (rmin.abs(), rmax.abs());
    let tube = 0.5 * (rmax - rmin);
    let major = 0.5 * (rmax + rmin);
    let (u, v, w) = frame(normal);
    let point = |i: usize, j: usize| {
        let theta = std::f64::consts::TAU * i as f64 / segments as f64;
        let phi = std::f64::consts::TAU * j as f64 / segments as f64;
        let radial = phi.cos() * u + phi.sin() * v;
        center + (major + tube * theta.cos()) * radial + tube * theta.sin() * w
    };
    let mut loops = Vec::with_capacity(segments * segments);
    for i in 0..segments {
        for j in 0..segments {
            let (i1, j1) = ((i + 1) % segments, (j + 1) % segments);
            // Around the axis, then around the tube: outward from the tube's core circle.
            loops.push(oriented(
                vec![point(i, j), point(i, j1), point(i1, j1), point(i1, j)],
                inward,
            ));
        }
    }
    Ok(loops)
}

/// `prism v1 .. vN length`: the face v1..vN, its copy moved by `length` against the face normal (so a
/// positive length faces outward, a negative one inward), and the side quads.
pub fn prism(base: &[DVec3], length: f64) -> Result<Vec<Loop>, String> {
    if base.len() < 3 {
        return Err("a prism needs at least three vertices".into());
    }
    if length == 0.0 {
        return Err("prism length is zero".into());
    }
    let newell = crate::geometry::vector_area(base);
    if newell.length() == 0.0 {
        return Err("prism base has zero area".into());
    }
    let offset = -length * newell.normalize();
    let top: Vec<DVec3> = base.iter().map(|p| *p + offset).collect();
    let mut loops = vec![base.to_vec(), top.iter().rev().copied().collect()];
    for k in 0..base.len() {
        let k1 = (k + 1) % base.len();
        loops.push(vec![base[k], top[k], top[k1], base[k1]]);
    }
    Ok(loops)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn area(l: &Loop) -> DVec3 {
        crate::geometry::vector_area(l)
    }

    fn centroid(l: &Loop) -> DVec3 {
        l.iter().copied().sum::<DVec3>() / l.len() as f64
    }

    /// Outward: each polygon's vector area points away from `inside`; returns the total area.
    fn check_outward(loops: &[Loop], inside: impl Fn(DVec3) -> DVec3) -> f64 {
        let mut total = 0.0;
        for l in loops {
            let a = area(l);
            let c = centroid(l);
            assert!(a.dot(c - inside(c)) > 0.0, "inward polygon {l:?}");
            total += a.length();
        }
        total
    }

    #[test]
    fn sphere_faces_out_and_converges() {
        let c = DVec3::new(1.0, 2.0, 3.0);
        let s16 = check_outward(&sphere(c, 2.0, 16).unwrap(), |_| c);
        let s64 = check_outward(&sphere(c, 2.0, 64).unwrap(), |_| c);
        let exact = 4.0 * PI * 4.0;
        assert!(s16 < exact && s64 < exact && s64 > s16);
        assert!((s64 - exact) / exact > -0.01);
        assert_eq!(sphere(c, 2.0, 16).unwrap().len(), 8 * 16);
        // Negative radius: every polygon points to the centre.
        for l in sphere(c, -2.0, 16).unwrap() {
            assert!(area(&l).dot(centroid(&l) - c) < 0.0);
        }
    }

    #[test]
    fn cylinder_cone_and_ring() {
        let (p1, p2) = (DVec3::ZERO, DVec3::new(0.0, 0.0, 3.0));
        let axis_point = |p: DVec3| DVec3::new(0.0, 0.0, p.z);
        let cyl = check_outward(&cone(p1, 1.0, p2, 1.0, 64).unwrap(), axis_point);
        assert!((cyl - 2.0 * PI * 3.0).abs() / (6.0 * PI) < 0.002);
        let tip = check_outward(&cone(p1, 1.0, p2, 0.0, 64).unwrap(), axis_point);
        let slant = (1.0f64 + 9.0).sqrt();
        assert!((tip - PI * slant).abs() / (PI * slant) < 0.002);
        assert!(cone(p1, 1.0, p2, -1.0, 8).is_err());
        assert!(cone(p1, 1.0, p1, 2.0, 8).is_err());
        let disc = ring(p1, DVec3::Z, 0.0, 1.0, 64).unwrap();
        let annulus = ring(p1, DVec3::Z, 0.5, 1.0, 64).unwrap();
        for l in disc.iter().chain(&annulus) {
            assert!(area(l).normalize().dot(DVec3::Z) > 0.999999);
        }
        let a: f64 = annulus.iter().map(|l| area(l).length()).sum();
        assert!((a - 0.75 * PI).abs() < 0.01);
        assert!(ring(p1, DVec3::Z, 1.0, 0.5, 8).is_err());
    }

    #[test]
    fn torus_faces_away_from_its_core() {
        let c = DVec3::ZERO;
        let core = |p: DVec3| {
            let radial = DVec3::new(p.x, p.y, 0.0).normalize();
            c + 1.5 * radial
        };
        let t = torus(c, DVec3::Z, 1.0, 2.0, 64).unwrap();
        let a = check_outward(&t, core);
        let exact = 4.0 * PI * PI * 1.5 * 0.5;
        assert!((a - exact).abs() / exact < 0.01);
        assert!(torus(c, DVec3::Z, 2.0, 1.0, 8).is_err());
        assert!(torus(c, DVec3::Z, -1.0, -2.0, 8).is_ok());
    }

    #[test]
    fn prism_is_closed_and_outward() {
        // The MGF manual's unit cube: base looks down -z, extruded to +z.
        let base = [
            DVec3::ZERO,
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
        ];
        let loops = prism(&base, 1.0).unwrap();
        assert_eq!(loops.len(), 6);
        let total = check_outward(&loops, |_| DVec3::splat(0.5));
        assert!((total - 6.0).abs() < 1e-12);
        let closed: DVec3 = loops.iter().map(area).sum();
        assert!(closed.length() < 1e-12);
        let inward = prism(&base, -1.0).unwrap();
        for l in &inward {
            assert!(area(l).dot(centroid(l) - DVec3::new(0.5, 0.5, -0.5)) < 0.0);
        }
    }
}

//! Push-pull (Hanrahan et al. 1991): irradiance gathered at any level of a patch's tree is pushed down to
//! the leaves, where B = E + ρ H, and radiance is pulled up as area-weighted averages so that links to
//! interior elements see the average of their children.

use crate::color::Rgb;
use crate::hierarchy::{ElementId, Hierarchy};
use std::f64::consts::PI;

/// New radiance of every element of one patch tree.
#[derive(Clone, Debug, Default)]
pub struct PatchUpdate {
    /// (element, new average radiance), for every element of the tree.
    pub radiance: Vec<(ElementId, Rgb)>,
    /// Power absorbed by the patch's leaves: Σ π A (1 - ρ) H, per channel.
    pub absorbed: Rgb,
    /// Exitant power of the leaves: Σ π A B, per channel.
    pub exitant: Rgb,
}

/// Pushes `gathered` (incident radiance gathered over each element's own links, indexed by element) down
/// the tree of `patch` and pulls the resulting radiance up.
pub fn push_pull(
    hierarchy: &Hierarchy,
    patch: u32,
    gathered: &dyn Fn(ElementId) -> Rgb,
) -> PatchUpdate {
    let p = &hierarchy.patches[patch as usize];
    let mut update = PatchUpdate::default();
    visit(
        hierarchy,
        p.root,
        Rgb::BLACK,
        p.emission,
        p.reflectance,
        gathered,
        &mut update,
    );
    update
}

fn visit(
    h: &Hierarchy,
    id: ElementId,
    down: Rgb,
    emission: Rgb,
    reflectance: Rgb,
    gathered: &dyn Fn(ElementId) -> Rgb,
    update: &mut PatchUpdate,
) -> Rgb {
    let e = h.element(id);
    let incident = down + gathered(id);
    let radiance = match e.children {
        None => {
            let b = emission + reflectance * incident;
            update.absorbed += (Rgb::WHITE - reflectance) * incident * (PI * e.area);
            update.exitant += b * (PI * e.area);
            b
        }
        Some(children) => {
            let mut sum = Rgb::BLACK;
            for c in children {
                let child_area = h.element(c).area;
                sum += visit(h, c, incident, emission, reflectance, gathered, update) * child_area;
            }
            sum / e.area
        }
    };
    update.radiance.push((id, radiance));
    radiance
}

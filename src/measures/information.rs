//! Information-theoretic scene measures (Feixas et al., "Information-theoretic oracle based on kernel
//! smoothness", §2.2 and §3.1, and their ref. \[5\], "An information theory framework for the analysis of
//! scene complexity"): discrete and continuous radiosity mutual information `I_r^d` (eq. 3) and `I_r^c`
//! (eq. 10), their visibility counterparts `I_v^d`, `I_v^c`, and the discretisation error
//! `Δ = (I^c − I^d) / I^c`. Logarithms are base 2 (bits).
//!
//! **Patches and form factors.** The patches `n_p` of eq. (3) are the leaves of the solved hierarchy, and
//! `F_ij` is the form factor the solver itself used between them: a link at (receiver R, source S) with
//! receiver-averaged form factor `F_RS` gathers the area-average radiosity of S, so every leaf r under R
//! receives from every leaf s under S with `F_rs = F_RS · A_s / A_S` (uniform over R, area-weighted within
//! S). This is exact for the solved system, not an approximation of it: with these `F_rs` the leaf
//! radiosities satisfy `B_r = E_r + ρ_r Σ_s F_rs B_s` (push-pull), so eq. (3)'s marginals are consistent.
//! Hierarchical refinement partitions each patch pair's product into link blocks, so each leaf pair has
//! one link and eq. (3) is evaluated block by block in O(links) (the sum over a block is separable).
//! Leaf-to-leaf form factors estimated by Monte Carlo were rejected: with fewer lines than leaf pairs the
//! empirical mutual information is biased upwards and exceeds `I^c`.
//!
//! The solver skips receivers that reflect nothing (ρ = 0); their rows are filled by reciprocity
//! (`A_s F_sr = A_r F_rs`). Surfaces that neither emit nor reflect take no part in the exchange: they have no
//! links, are absent from the discrete system, and global-line samples touching them are dropped.
//!
//! **Incoming radiosity.** `B_i^in = (B_i − E_i)/ρ_i` is used through the identity `B_i^in = Σ_j F_ij B_j`,
//! which equals it for the solved system and stays defined where `ρ_i = 0` (light sources). With it eq. (3)
//! is the mutual information of the joint distribution `p_ij = A_i F_ij B_i B_j / 𝒜_T`, `𝒜_T = Σ_i A_i
//! B_i^in B_i`, and needs neither ρ nor E.
//!
//! **Degenerate terms.** Terms with `p_ij = 0` (`F_ij = 0`, `B_i = 0` or `B_j = 0`; a zero `B_i^in` forces
//! all of row i to zero) count as `0 log 0 = 0`. Global-line samples whose leaves carry no probability in the
//! discrete system (`B^in = 0` although the line found a visible lit surface: a link form factor estimated
//! as zero) are dropped and counted in [`InformationMeasures::dropped_samples`]. When `I^c ≤ 0`, Δ is 0.
//!
//! **Colour.** The measures are computed on the channel average of the RGB radiosity.
//!
//! **Visibility measures.** `I_v^d` and `I_v^c` are the radiosity ones with `B ≡ 1`: then `B_i^in = Σ_j
//! F_ij`, which is 1 in a closed scene, `𝒜_T = A_T` and eq. (3) becomes ref. \[5\]'s `I_v^d = Σ_ij (A_i/A_T)
//! F_ij log(F_ij A_T / A_j)` and eq. (10) its `I_v^c = (1/N) Σ log(A_T cos θx cos θy / (π d²))`. In an open
//! scene (`Σ_j F_ij < 1`) this is the mutual information of the lines that join two surfaces, which stays
//! non-negative where ref. \[5\]'s closed-scene formula would not.

use super::global_lines::GlobalLines;
use crate::geometry::form_factor::point_to_point;
use crate::hierarchy::{ElementId, Hierarchy};
use crate::scene::Scene;
use rayon::prelude::*;
use serde::Serialize;
use std::ops::Range;

/// A block of the leaf-to-leaf form factor matrix: every leaf in `receiver` sees every leaf s in `source`
/// with form factor `form_factor · A_s / A_source`.
#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    pub receiver: Range<usize>,
    pub source: Range<usize>,
    /// Receiver-averaged form factor from the receiver group to the whole source group.
    pub form_factor: f64,
}

/// The discrete system of eq. (3): leaf areas and form factor blocks that cover each leaf pair at most
/// once.
#[derive(Clone, Debug, PartialEq)]
pub struct LeafSystem {
    pub area: Vec<f64>,
    pub blocks: Vec<Block>,
}

impl LeafSystem {
    /// A dense system: `form_factors[i][j] = F_ij` between `area.len()` patches.
    pub fn dense(area: Vec<f64>, form_factors: &[Vec<f64>]) -> Self {
        let mut blocks = Vec::new();
        for (i, row) in form_factors.iter().enumerate() {
            for (j, &f) in row.iter().enumerate() {
                if f > 0.0 {
                    blocks.push(Block {
                        receiver: i..i + 1,
                        source: j..j + 1,
                        form_factor: f,
                    });
                }
            }
        }
        LeafSystem { area, blocks }
    }

    /// Incoming radiosity `B_i^in = Σ_j F_ij B_j` of every leaf.
    pub fn incoming(&self, b: &[f64]) -> Vec<f64> {
        let (area_sum, power_sum) = (prefix(&self.area), prefix_product(&self.area, b));
        let mut diff = vec![0.0; self.area.len() + 1];
        for block in &self.blocks {
            let a_s = range_sum(&area_sum, &block.source);
            if a_s <= 0.0 {
                continue;
            }
            let v = block.form_factor * range_sum(&power_sum, &block.source) / a_s;
            diff[block.receiver.start] += v;
            diff[block.receiver.end] -= v;
        }
        let mut acc = 0.0;
        diff[..self.area.len()]
            .iter()
            .map(|d| {
                acc += d;
                acc.max(0.0)
            })
            .collect()
    }

    /// `𝒜_T = Σ_i A_i B_i^in B_i`, the normalisation of eqs. (3) and (10).
    pub fn total(&self, b: &[f64], incoming: &[f64]) -> f64 {
        (0..self.area.len())
            .map(|i| self.area[i] * b[i] * incoming[i])
            .sum()
    }

    /// Discrete mutual information, eq. (3), for leaf radiosities `b` (`b ≡ 1` gives `I_v^d`). Per block,
    /// `Σ_rs u_r u_s (F/A_S)/𝒜_T · log(F 𝒜_T / (A_S B_r^in B_s^in))` with `u = A B` separates into sums of
    /// `u` and `u log B^in` over the receiver and source ranges.
    pub fn discrete_information(&self, b: &[f64]) -> f64 {
        let incoming = self.incoming(b);
        let total = self.total(b, &incoming);
        if total <= 0.0 {
            return 0.0;
        }
        let u: Vec<f64> = (0..self.area.len()).map(|i| self.area[i] * b[i]).collect();
        // log B^in is only ever multiplied by u_r and by sources with u_s > 0 seen through F > 0, which
        // vanish together with B^in; 0 keeps 0·log 0 = 0.
        let log_in: Vec<f64> = incoming
            .iter()
            .map(|&x| if x > 0.0 { x.log2() } else { 0.0 })
            .collect();
        let (area_sum, u_sum, ul_sum) =
            (prefix(&self.area), prefix(&u), prefix_product(&u, &log_in));
        let mut sum = 0.0;
        for block in &self.blocks {
            let a_s = range_sum(&area_sum, &block.source);
            let (u_r, u_s) = (
                range_sum(&u_sum, &block.receiver),
                range_sum(&u_sum, &block.source),
            );
            if block.form_factor <= 0.0 || a_s <= 0.0 || u_r <= 0.0 || u_s <= 0.0 {
                continue;
            }
            let (l_r, l_s) = (
                range_sum(&ul_sum, &block.receiver),
                range_sum(&ul_sum, &block.source),
            );
            let k = block.form_factor / a_s;
            sum += k * ((k * total).log2() * u_r * u_s - l_r * u_s - u_r * l_s);
        }
        sum / total
    }
}

fn prefix(v: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(v.len() + 1);
    let mut acc = 0.0;
    out.push(0.0);
    for x in v {
        acc += x;
        out.push(acc);
    }
    out
}

fn prefix_product(a: &[f64], b: &[f64]) -> Vec<f64> {
    let v: Vec<f64> = a.iter().zip(b).map(|(x, y)| x * y).collect();
    prefix(&v)
}

fn range_sum(prefix: &[f64], r: &Range<usize>) -> f64 {
    prefix[r.end] - prefix[r.start]
}

/// The leaves of a solved hierarchy as the patches of eq. (3), with the solver's links as form factor
/// blocks.
#[derive(Clone, Debug)]
pub struct HierarchyLeaves {
    pub system: LeafSystem,
    /// Leaf element ids in system order (tree order: every element's leaves are contiguous).
    pub leaves: Vec<ElementId>,
    /// Channel-average radiosity of each leaf.
    pub radiosity: Vec<f64>,
}

impl HierarchyLeaves {
    pub fn new(hierarchy: &Hierarchy) -> anyhow::Result<Self> {
        let leaves = hierarchy.leaves();
        let n = hierarchy.elements.len();
        let mut range: Vec<Option<Range<usize>>> = vec![None; n];
        let mut count = vec![0usize; n];
        for (k, &leaf) in leaves.iter().enumerate() {
            let mut e = Some(leaf);
            while let Some(id) = e {
                let r = range[id as usize].get_or_insert(k..k + 1);
                r.start = r.start.min(k);
                r.end = r.end.max(k + 1);
                count[id as usize] += 1;
                e = hierarchy.element(id).parent();
            }
        }
        let mut blocks = Vec::new();
        for (id, element) in hierarchy.elements.iter().enumerate() {
            for link in &element.links {
                let receiver = group(&range, &count, id)?;
                let source = group(&range, &count, link.source as usize)?;
                // The solver never links into a patch that reflects nothing (its gather is useless), but
                // light still arrives there: its row comes from reciprocity, A_S F_SR = A_R F_RS.
                if hierarchy.reflectance_of(link.source).is_black() {
                    blocks.push(Block {
                        receiver: source.clone(),
                        source: receiver.clone(),
                        form_factor: element.area * link.form_factor()
                            / hierarchy.element(link.source).area,
                    });
                }
                blocks.push(Block {
                    receiver,
                    source,
                    form_factor: link.form_factor(),
                });
            }
        }
        let area = leaves.iter().map(|&l| hierarchy.element(l).area).collect();
        let radiosity = leaves
            .iter()
            .map(|&l| hierarchy.average_radiance(l).average())
            .collect();
        Ok(HierarchyLeaves {
            system: LeafSystem { area, blocks },
            leaves,
            radiosity,
        })
    }
}

/// The contiguous leaf range of an element (clusters spanning several patches are not supported).
fn group(
    range: &[Option<Range<usize>>],
    count: &[usize],
    id: usize,
) -> anyhow::Result<Range<usize>> {
    match &range[id] {
        Some(r) if r.len() == count[id] => Ok(r.clone()),
        _ => anyhow::bail!("element {id}: its leaves are not one patch subtree (clusters are not supported by the information measures)"),
    }
}

/// A Monte Carlo estimate with its standard error.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Estimate {
    pub value: f64,
    pub std_error: f64,
}

/// Continuous mutual information, eq. (10), by global lines, for leaf radiosities `b` (`b ≡ 1` gives
/// `I_v^c`), with `B^in` and `𝒜_T` of the discrete system (piecewise constant radiosity, as the paper
/// prescribes). Every chord is two samples, x→y and y→x, each weighted by its polygon's area over its
/// crossings. Returns the estimate and the number of dropped samples.
pub fn continuous_information(
    scene: &Scene,
    hierarchy: &Hierarchy,
    leaves: &HierarchyLeaves,
    b: &[f64],
    lines: &GlobalLines,
) -> (Estimate, usize) {
    let system = &leaves.system;
    let incoming = system.incoming(b);
    let total = system.total(b, &incoming);
    if total <= 0.0 || lines.lines == 0 {
        return (Estimate::default(), 0);
    }
    let mut index = vec![usize::MAX; hierarchy.elements.len()];
    for (k, &leaf) in leaves.leaves.iter().enumerate() {
        index[leaf as usize] = k;
    }
    let per_line: Vec<(f64, usize)> = (0..lines.lines)
        .into_par_iter()
        .map(|k| {
            let (mut s, mut dropped) = (0.0, 0usize);
            for chord in lines.line(k) {
                let (Some(px), Some(py)) = (chord.patch_x, chord.patch_y) else {
                    continue;
                };
                let i = index[hierarchy.locate(px, chord.x) as usize];
                let j = index[hierarchy.locate(py, chord.y) as usize];
                let bb = b[i] * b[j];
                if bb <= 0.0 {
                    continue;
                }
                let kernel = point_to_point(
                    chord.x,
                    hierarchy.patches[px as usize].normal,
                    chord.y,
                    hierarchy.patches[py as usize].normal,
                );
                let denominator = incoming[i] * incoming[j];
                if kernel <= 0.0 || denominator <= 0.0 {
                    dropped += 2;
                    continue;
                }
                let weight =
                    lines.weight(scene, chord.polygon_x) + lines.weight(scene, chord.polygon_y);
                s += weight * bb / total * (total * kernel / denominator).log2();
            }
            (s, dropped)
        })
        .collect();
    let dropped = per_line.iter().map(|p| p.1).sum();
    let per_line: Vec<f64> = per_line.into_iter().map(|p| p.0).collect();
    let n = per_line.len() as f64;
    let value: f64 = per_line.iter().sum();
    let mean = value / n;
    let variance = if n > 1.0 {
        per_line.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (
        Estimate {
            value,
            std_error: (n * variance).sqrt(),
        },
        dropped,
    )
}

/// Relative discretisation error `Δ = (I^c − I^d) / I^c` (§2.2); 0 when `I^c ≤ 0`.
pub fn discretisation_error(continuous: f64, discrete: f64) -> f64 {
    if continuous > 0.0 {
        (continuous - discrete) / continuous
    } else {
        0.0
    }
}

/// All measures of one solution, as written to the stats JSON.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct InformationMeasures {
    /// Discrete radiosity mutual information, eq. (3), in bits.
    #[serde(rename = "I_r_d")]
    pub radiosity_discrete: f64,
    /// Continuous radiosity mutual information, eq. (10), in bits.
    #[serde(rename = "I_r_c")]
    pub radiosity_continuous: f64,
    #[serde(rename = "I_r_c_std_error")]
    pub radiosity_continuous_error: f64,
    /// `(I_r^c − I_r^d) / I_r^c`.
    pub delta: f64,
    #[serde(rename = "I_v_d")]
    pub visibility_discrete: f64,
    #[serde(rename = "I_v_c")]
    pub visibility_continuous: f64,
    #[serde(rename = "I_v_c_std_error")]
    pub visibility_continuous_error: f64,
    /// `(I_v^c − I_v^d) / I_v^c`.
    pub delta_v: f64,
    pub leaves: usize,
    pub lines: usize,
    /// Radiosity samples dropped because their leaves have no incoming radiosity in the discrete system.
    pub dropped_samples: usize,
}

/// Measures a solved hierarchy with the given global lines (traced on the same scene).
pub fn measure(
    scene: &Scene,
    hierarchy: &Hierarchy,
    lines: &GlobalLines,
) -> anyhow::Result<InformationMeasures> {
    let leaves = HierarchyLeaves::new(hierarchy)?;
    let ones = vec![1.0; leaves.leaves.len()];
    let radiosity_discrete = leaves.system.discrete_information(&leaves.radiosity);
    let (rc, dropped) = continuous_information(scene, hierarchy, &leaves, &leaves.radiosity, lines);
    let visibility_discrete = leaves.system.discrete_information(&ones);
    let (vc, _) = continuous_information(scene, hierarchy, &leaves, &ones, lines);
    Ok(InformationMeasures {
        radiosity_discrete,
        radiosity_continuous: rc.value,
        radiosity_continuous_error: rc.std_error,
        delta: discretisation_error(rc.value, radiosity_discrete),
        visibility_discrete,
        visibility_continuous: vc.value,
        visibility_continuous_error: vc.std_error,
        delta_v: discretisation_error(vc.value, visibility_discrete),
        leaves: leaves.leaves.len(),
        lines: lines.lines,
        dropped_samples: dropped,
    })
}

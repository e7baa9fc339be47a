//! MGF transform arguments (`xf` and `i` lines): `-t dx dy dz`, `-rx/-ry/-rz degrees`, `-s factor`,
//! `-mx/-my/-mz`, `-i N` (repeat the following arguments N times) and `-a N` (an array of N instances).
//!
//! Arguments act in order, each on the result of the previous ones. An `-i N` or `-a N` starts a group
//! that runs to the next `-i`/`-a`; the group is applied N times (`-i`) or k times in array instance k =
//! 0..N-1 (`-a`). Several `-a` make a multi-dimensional array whose last index varies fastest. This is
//! the behaviour of Ward's MGF parser library (`xf.c`).

use glam::{DAffine3, DMat3, DVec3};

/// Largest total number of array instances one `xf` may create.
const MAX_INSTANCES: usize = 1_000_000;
/// Largest `-i` repeat count.
const MAX_REPEAT: usize = 100_000;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Repeat {
    Times(usize),
    /// Repeated by the current index of array dimension `d`.
    Array(usize),
}

#[derive(Clone, Debug, PartialEq)]
struct Group {
    repeat: Repeat,
    step: DAffine3,
}

/// A parsed transform specification with its array dimensions.
#[derive(Clone, Debug, PartialEq)]
pub struct XfSpec {
    groups: Vec<Group>,
    /// Sizes of the `-a` dimensions, in order.
    pub dims: Vec<usize>,
}

impl XfSpec {
    /// The transform of array instance `index` (one index per dimension).
    pub fn matrix(&self, index: &[usize]) -> DAffine3 {
        let mut m = DAffine3::IDENTITY;
        for g in &self.groups {
            let n = match g.repeat {
                Repeat::Times(n) => n,
                Repeat::Array(d) => index[d],
            };
            m = power(g.step, n) * m;
        }
        m
    }

    /// Moves `index` to the next array instance (odometer, last dimension fastest); false after the last.
    pub fn advance(&self, index: &mut [usize]) -> bool {
        for d in (0..self.dims.len()).rev() {
            index[d] += 1;
            if index[d] < self.dims[d] {
                return true;
            }
            index[d] = 0;
        }
        false
    }
}

/// `step` applied `n` times, by repeated squaring (an array of a million instances stays linear).
fn power(step: DAffine3, mut n: usize) -> DAffine3 {
    let (mut result, mut base) = (DAffine3::IDENTITY, step);
    while n > 0 {
        if n & 1 == 1 {
            result = base * result;
        }
        base = base * base;
        n >>= 1;
    }
    result
}

fn number(args: &[&str], k: usize, flag: &str) -> Result<f64, String> {
    let word = args
        .get(k)
        .ok_or_else(|| format!("transform flag {flag} is missing an argument"))?;
    super::parse_number(word)
}

fn count(args: &[&str], k: usize, flag: &str) -> Result<usize, String> {
    let word = args
        .get(k)
        .ok_or_else(|| format!("transform flag {flag} is missing its count"))?;
    word.parse::<usize>()
        .map_err(|_| format!("transform flag {flag} needs a non-negative integer, not '{word}'"))
}

/// Parses transform arguments (the words after `xf`, or after the file name of `i`).
pub fn parse(args: &[&str]) -> Result<XfSpec, String> {
    let mut groups = Vec::new();
    let mut dims = Vec::new();
    let mut current = Group {
        repeat: Repeat::Times(1),
        step: DAffine3::IDENTITY,
    };
    let mut k = 0;
    while k < args.len() {
        let flag = args[k];
        let op = match flag {
            "-t" => {
                let v = DVec3::new(
                    number(args, k + 1, flag)?,
                    number(args, k + 2, flag)?,
                    number(args, k + 3, flag)?,
                );
                k += 4;
                DAffine3::from_translation(v)
            }
            "-rx" | "-ry" | "-rz" => {
                let a = number(args, k + 1, flag)?.to_radians();
                k += 2;
                DAffine3::from_mat3(match flag {
                    "-rx" => DMat3::from_rotation_x(a),
                    "-ry" => DMat3::from_rotation_y(a),
                    _ => DMat3::from_rotation_z(a),
                })
            }
            "-s" => {
                let s = number(args, k + 1, flag)?;
                if s == 0.0 {
                    return Err("transform scale factor is zero".into());
                }
                k += 2;
                DAffine3::from_scale(DVec3::splat(s))
            }
            "-mx" | "-my" | "-mz" => {
                k += 1;
                DAffine3::from_scale(match flag {
                    "-mx" => DVec3::new(-1.0, 1.0, 1.0),
                    "-my" => DVec3::new(1.0, -1.0, 1.0),
                    _ => DVec3::new(1.0, 1.0, -1.0),
                })
            }
            "-i" | "-a" => {
                let n = count(args, k + 1, flag)?;
                k += 2;
                groups.push(current);
                let repeat = if flag == "-i" {
                    if n > MAX_REPEAT {
                        return Err(format!("transform repeat count {n} is too large"));
                    }
                    Repeat::Times(n)
                } else {
                    if n == 0 {
                        return Err("array size must be at least 1".into());
                    }
                    dims.push(n);
                    if dims
                        .iter()
                        .try_fold(1usize, |a, &d| a.checked_mul(d))
                        .is_none_or(|total| total > MAX_INSTANCES)
                    {
                        return Err(format!(
                            "transform array has more than {MAX_INSTANCES} instances"
                        ));
                    }
                    Repeat::Array(dims.len() - 1)
                };
                current = Group {
                    repeat,
                    step: DAffine3::IDENTITY,
                };
                continue;
            }
            other => return Err(format!("unknown transform argument '{other}'")),
        };
        current.step = op * current.step;
    }
    groups.push(current);
    Ok(XfSpec { groups, dims })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(s: &str) -> Vec<&str> {
        s.split_whitespace().collect()
    }

    #[test]
    fn arguments_act_in_order() {
        // Rotate about the y-parallel axis through (15, 0, -35): the manual's example.
        let spec = parse(&words("-t -15 0 35 -ry -20 -t 15 0 -35")).unwrap();
        let m = spec.matrix(&[]);
        let c = DVec3::new(15.0, 0.0, -35.0);
        assert!((m.transform_point3(c) - c).length() < 1e-12);
        let m = parse(&words("-rz 90 -t 1 0 0")).unwrap().matrix(&[]);
        assert!((m.transform_point3(DVec3::X) - DVec3::new(1.0, 1.0, 0.0)).length() < 1e-12);
        let m = parse(&words("-s 2 -mx")).unwrap().matrix(&[]);
        assert!(m.matrix3.determinant() < 0.0);
        assert!((m.transform_point3(DVec3::ONE) - DVec3::new(-2.0, 2.0, 2.0)).length() < 1e-12);
    }

    #[test]
    fn repeats_and_arrays() {
        let m = parse(&words("-t 1 0 0 -i 3 -t 0 2 0")).unwrap().matrix(&[]);
        assert!((m.transform_point3(DVec3::ZERO) - DVec3::new(1.0, 6.0, 0.0)).length() < 1e-12);
        // The manual's 3 x 5 grid of spheres.
        let spec = parse(&words("-t 1 1 10 -a 3 -t 3 0 0 -a 5 -t 0 3 0")).unwrap();
        assert_eq!(spec.dims, vec![3, 5]);
        let mut index = vec![0, 0];
        let mut seen = vec![spec.matrix(&index).transform_point3(DVec3::ZERO)];
        while spec.advance(&mut index) {
            seen.push(spec.matrix(&index).transform_point3(DVec3::ZERO));
        }
        assert_eq!(seen.len(), 15);
        assert_eq!(seen[1], DVec3::new(1.0, 4.0, 10.0));
        assert_eq!(seen[14], DVec3::new(7.0, 13.0, 10.0));
    }

    #[test]
    fn bad_arguments() {
        for bad in [
            "-t 1 2",
            "-q",
            "-s 0",
            "-a 0",
            "-a x",
            "-rx nan",
            "-a 1000 -a 1000 -a 10",
        ] {
            assert!(parse(&words(bad)).is_err(), "{bad}");
        }
    }
}

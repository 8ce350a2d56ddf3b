//! The categorical critic's support and the two ways its targets are built (`docs/sac-lsp.md` §13):
//! C51's projection of a shifted and scaled distribution onto the support (soft C51), and the
//! dissertation code's per-sample scalar (`sac-c51`'s `project_TZ`). Both work on plain rows of
//! probabilities: targets carry no gradient, so they are computed here and handed to candle as
//! constants.

use crate::config::CategoricalConfig;

/// The fixed atoms z_i = v_min + i dz, i = 0..atoms.
#[derive(Clone, Debug, PartialEq)]
pub struct Support {
    atoms: usize,
    v_min: f64,
    v_max: f64,
    dz: f64,
}

impl Support {
    /// The support of a (validated) categorical configuration.
    pub fn new(cfg: &CategoricalConfig) -> Self {
        let (v_min, v_max) = (f64::from(cfg.v_min), f64::from(cfg.v_max));
        Self { atoms: cfg.atoms, v_min, v_max, dz: (v_max - v_min) / (cfg.atoms - 1) as f64 }
    }

    /// Number of atoms.
    pub fn atoms(&self) -> usize {
        self.atoms
    }

    /// Every atom's value, ascending.
    pub fn values(&self) -> Vec<f32> {
        (0..self.atoms).map(|i| self.atom(i) as f32).collect()
    }

    fn atom(&self, i: usize) -> f64 {
        self.v_min + i as f64 * self.dz
    }

    /// C51's projection (Bellemare et al. 2017, Algorithm 1) of the distribution that puts mass
    /// `probs[j]` on `shift + scale * z_j`, onto the support: each moved atom is clipped to
    /// [v_min, v_max] and its mass split between the two neighbouring atoms in proportion to
    /// closeness. Mass is conserved, and the mean is `shift + scale * mean` whenever no atom is
    /// clipped. Adds into `out` (one row of `atoms`).
    pub fn project_into(&self, probs: &[f32], shift: f64, scale: f64, out: &mut [f32]) {
        for (j, &p) in probs.iter().enumerate() {
            let tz = (shift + scale * self.atom(j)).clamp(self.v_min, self.v_max);
            let b = ((tz - self.v_min) / self.dz).clamp(0.0, (self.atoms - 1) as f64);
            let (l, u) = (b.floor() as usize, b.ceil() as usize);
            if l == u {
                // The moved atom sits on an atom: all its mass goes there (C51's l == u case).
                out[l] += p;
            } else {
                out[l] += p * (u as f64 - b) as f32;
                out[u] += p * (b - l as f64) as f32;
            }
        }
    }

    /// [`project_into`](Self::project_into) for a batch: row i of `probs` (`[rows, atoms]`) moved by
    /// `shifts[i]` and `scales[i]`, as `[rows, atoms]`.
    pub fn project(&self, probs: &[f32], shifts: &[f64], scales: &[f64]) -> Vec<f32> {
        let mut out = vec![0.0; probs.len()];
        for (i, row) in probs.chunks_exact(self.atoms).enumerate() {
            self.project_into(row, shifts[i], scales[i], &mut out[i * self.atoms..(i + 1) * self.atoms]);
        }
        out
    }

    /// The dissertation code's bracketing of the moved support (`sac-c51/sac/algos/sac.py`,
    /// `project_TZ`): for row i, Tz_j = clip(shift_i + scale_i z_j, v_min, v_max - 1e-4),
    /// b = (Tz_j - v_min) / dz, l = floor b, u = l + 1. Returns the indices l and u and the weights
    /// u - b and b - l, each `[rows, atoms]`; the code then sums
    /// (u - b) log p[l] + (b - l) log p[u] over j for whatever distribution p it is given.
    pub fn dissertation_brackets(&self, shifts: &[f64], scales: &[f64]) -> Brackets {
        let n = shifts.len() * self.atoms;
        let mut out = Brackets {
            lower: Vec::with_capacity(n),
            upper: Vec::with_capacity(n),
            lower_weight: Vec::with_capacity(n),
            upper_weight: Vec::with_capacity(n),
        };
        for (&shift, &scale) in shifts.iter().zip(scales) {
            for j in 0..self.atoms {
                let tz = (shift + scale * self.atom(j)).clamp(self.v_min, self.v_max - 1e-4);
                let b = (tz - self.v_min) / self.dz;
                // In f32, as TensorFlow ran it, v_max - 1e-4 can round up to v_max and make
                // u = atoms; clamping l keeps both indices on the support with the same weights.
                let l = (b.floor() as usize).min(self.atoms - 2);
                out.lower.push(l as u32);
                out.upper.push(l as u32 + 1);
                out.lower_weight.push((l as f64 + 1.0 - b) as f32);
                out.upper_weight.push((b - l as f64) as f32);
            }
        }
        out
    }
}

/// The output of [`Support::dissertation_brackets`], each `[rows, atoms]` row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Brackets {
    /// Index l of each moved atom.
    pub lower: Vec<u32>,
    /// Index u = l + 1.
    pub upper: Vec<u32>,
    /// u - b.
    pub lower_weight: Vec<f32>,
    /// b - l.
    pub upper_weight: Vec<f32>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn support(atoms: usize, v_min: f32, v_max: f32) -> Support {
        Support::new(&CategoricalConfig { atoms, v_min, v_max, ..CategoricalConfig::default() })
    }

    fn mean(s: &Support, p: &[f32]) -> f64 {
        s.values().iter().zip(p).map(|(z, p)| f64::from(*z) * f64::from(*p)).sum()
    }

    #[test]
    fn projection_matches_hand_worked_cases() {
        // Atoms -1, 0, 1, 2.
        let s = support(4, -1.0, 2.0);
        // A point mass on 0 moved by +0.25: 0.25 lies between atoms 0 and 1, a quarter of the way.
        assert_eq!(s.project(&[0.0, 1.0, 0.0, 0.0], &[0.25], &[1.0]), vec![0.0, 0.75, 0.25, 0.0]);
        // Halving the support (scale 0.5) maps atoms to -0.5, 0, 0.5, 1.
        assert_eq!(
            s.project(&[0.25, 0.25, 0.25, 0.25], &[0.0], &[0.5]),
            vec![0.125, 0.125 + 0.25 + 0.125, 0.125 + 0.25, 0.0]
        );
        // Beyond the support, mass is clipped onto the end atoms.
        assert_eq!(s.project(&[0.5, 0.0, 0.0, 0.5], &[10.0], &[1.0]), vec![0.0, 0.0, 0.0, 1.0]);
        assert_eq!(s.project(&[0.5, 0.0, 0.0, 0.5], &[-10.0], &[1.0]), vec![1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn a_terminal_transition_puts_all_mass_around_the_reward() {
        // scale = gamma (1 - d) = 0: every atom moves onto the reward 0.5, split between 0 and 1.
        let s = support(4, -1.0, 2.0);
        assert_eq!(s.project(&[0.1, 0.2, 0.3, 0.4], &[0.5], &[0.0]), vec![0.0, 0.5, 0.5, 0.0]);
    }

    #[test]
    fn projection_conserves_mass_and_the_mean_inside_the_support() {
        let s = support(51, -100.0, 5000.0);
        let p: Vec<f32> = (0..51).map(|i| (i * 7 % 13) as f32 + 1.0).collect();
        let total: f32 = p.iter().sum();
        let p: Vec<f32> = p.iter().map(|x| x / total).collect();
        for (shift, scale) in [(3.0, 0.99), (-40.0, 0.5), (1e4, 0.99), (0.0, 0.0)] {
            let m = s.project(&p, &[shift], &[scale]);
            assert!((m.iter().sum::<f32>() - 1.0).abs() < 1e-5, "mass {shift} {scale}");
            assert!(m.iter().all(|x| *x >= 0.0));
        }
        // With every moved atom inside the support, the mean moves exactly as the scalar target.
        let narrow: Vec<f32> = (0..51).map(|i| if (10..20).contains(&i) { 0.1 } else { 0.0 }).collect();
        let m = s.project(&narrow, &[25.0], &[0.99]);
        let expected = 25.0 + 0.99 * mean(&s, &narrow);
        assert!((mean(&s, &m) - expected).abs() < 1e-2, "{} vs {expected}", mean(&s, &m));
    }

    #[test]
    fn a_point_mass_target_has_the_scalar_targets_mean() {
        // V-bar a point mass on atom k: the projected target's mean is scale r + gamma V-bar.
        let s = support(51, -100.0, 5000.0);
        for k in [0, 7, 30, 49] {
            let mut p = vec![0.0; 51];
            p[k] = 1.0;
            let (r, gamma) = (12.5, 0.99);
            let m = s.project(&p, &[r], &[gamma]);
            let scalar = r + gamma * f64::from(s.values()[k]);
            assert!((mean(&s, &m) - scalar).abs() < 1e-3, "atom {k}: {} vs {scalar}", mean(&s, &m));
        }
    }

    #[test]
    fn dissertation_brackets_are_the_codes() {
        let s = support(51, -100.0, 5000.0);
        let b = s.dissertation_brackets(&[10.0], &[0.99]);
        // z_0 = -100 moves to 10 - 99 = -89: b = 11 / 102.
        assert_eq!((b.lower[0], b.upper[0]), (0, 1));
        assert!((b.upper_weight[0] - 11.0 / 102.0).abs() < 1e-6);
        assert!((b.lower_weight[0] + b.upper_weight[0] - 1.0).abs() < 1e-6);
        // z_50 = 5000 moves to 4960, below v_max; far above, the clip keeps u on the support.
        let far = s.dissertation_brackets(&[1e6], &[1.0]);
        assert!(far.upper.iter().all(|u| *u == 50) && far.lower.iter().all(|l| *l == 49));
    }
}

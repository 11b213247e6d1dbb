//! The regressors of a free correction `c = w . phi`.
//!
//! *Present* features see everything the model knows at time `t`: its inputs, measured and
//! hidden states (z-scored and clipped to [`CLIP`]), and the value `l` of the corrected
//! quantity itself (a let's value, or the state of a corrected balance; divided by its root
//! mean square). They are the quadratic monomials `q = [1, v_j, v_j v_k]` of the variables
//! and the same multiplied by `l`, so that additive (`c = g(v)`) and multiplicative
//! (`c = l g(v)`) corrections are both within reach.
//!
//! *History* features add a fading memory ([`super::memory`]): the inputs, the measured
//! states and `l` passed through first-order filters at each time constant, each filtered
//! value `w` alone and times `l`.

/// Z-scored variables are clipped to this many standard deviations, so a correction stays
/// bounded when a free run leaves the training range.
pub const CLIP: f64 = 4.0;

/// Most quadratic monomials a sparse refinement adjusts ([`FeatureMap::sparse_directions`]).
pub const SPARSE_QUADRATIC_UP_TO: usize = 30;

/// How to turn variables into features.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureMap {
    /// Mean of each present variable (inputs, measured states, hidden states).
    pub center: Vec<f64>,
    /// Standard deviation of each present variable.
    pub scale: Vec<f64>,
    /// Root mean square of the corrected quantity.
    pub locus_scale: f64,
    /// Number of filtered variables besides `l` (inputs, then measured states: the first of
    /// `center`).
    pub embedded: usize,
    /// The filters' time constants, if the map has history.
    pub taus: Option<Vec<f64>>,
}

impl FeatureMap {
    /// Number of present variables.
    fn variables(&self) -> usize {
        self.center.len()
    }

    /// Number of quadratic monomials.
    fn quadratic(&self) -> usize {
        let v = self.variables();
        1 + v + v * (v + 1) / 2
    }

    /// Number of filtered signals per time constant (the embedded variables and `l`).
    pub fn signals(&self) -> usize {
        self.embedded + 1
    }

    /// Number of features.
    pub fn width(&self) -> usize {
        let filtered = self.taus.as_ref().map_or(0, |t| t.len() * self.signals());
        2 * self.quadratic() + 2 * filtered
    }

    /// Indices of the features a free-run refinement adjusts: the constant and `l` alone (a
    /// constant offset and a term proportional to the corrected quantity), and with history
    /// the filtered `l` alone at each time constant (a lag of the corrected quantity).
    pub fn directions(&self) -> Vec<usize> {
        let q = self.quadratic();
        let mut directions = vec![0, q];
        if let Some(taus) = &self.taus {
            let block = 2;
            for t in 0..taus.len() {
                let signal = t * self.signals() + self.embedded;
                directions.push(2 * q + signal * block);
            }
        }
        directions
    }

    /// The directions of a refinement grown from no correction (sparse records): every
    /// quadratic monomial of the present variables when there are at most
    /// [`SPARSE_QUADRATIC_UP_TO`] of them, else the constant and the linear ones; and `l`.
    pub fn sparse_directions(&self) -> Vec<usize> {
        let q = self.quadratic();
        let mut directions: Vec<usize> = if q <= SPARSE_QUADRATIC_UP_TO {
            (0..q).collect()
        } else {
            (0..=self.variables()).collect()
        };
        directions.push(q);
        directions
    }

    fn normalise(&self, index: usize, value: f64) -> f64 {
        ((value - self.center[index]) / self.scale[index]).clamp(-CLIP, CLIP)
    }

    fn locus(&self, value: f64) -> f64 {
        (value / self.locus_scale).clamp(-2.0 * CLIP, 2.0 * CLIP)
    }

    /// Writes the features into `out` (cleared first). `present` holds the present
    /// variables, `locus` the corrected quantity, `filtered` the filtered signals (the
    /// embedded variables, then `l`) at each time constant, time-constant-major, as raw
    /// values.
    pub fn features(&self, present: &[f64], locus: f64, filtered: &[f64], out: &mut Vec<f64>) {
        out.clear();
        let v: Vec<f64> = (present.iter().enumerate())
            .map(|(j, &x)| self.normalise(j, x))
            .collect();
        let l = self.locus(locus);
        out.push(1.0);
        out.extend_from_slice(&v);
        for j in 0..v.len() {
            for k in j..v.len() {
                out.push(v[j] * v[k]);
            }
        }
        let quadratic = out.len();
        for q in 0..quadratic {
            out.push(l * out[q]);
        }
        if self.taus.is_some() {
            for (index, &raw) in filtered.iter().enumerate() {
                let signal = index % self.signals();
                let w = if signal < self.embedded {
                    self.normalise(signal, raw)
                } else {
                    self.locus(raw)
                };
                out.push(w);
                out.push(l * w);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn features_are_the_documented_monomials() {
        let map = FeatureMap {
            center: vec![1.0, 0.0],
            scale: vec![2.0, 1.0],
            locus_scale: 0.5,
            embedded: 1,
            taus: Some(vec![3.0]),
        };
        let mut out = Vec::new();
        // v = [(3 - 1) / 2, -1] = [1, -1]; l = 0.25 / 0.5 = 0.5; filtered embedded
        // w = (5 - 1) / 2 = 2, filtered l: 1 / 0.5 = 2.
        map.features(&[3.0, -1.0], 0.25, &[5.0, 1.0], &mut out);
        let q = [1.0, 1.0, -1.0, 1.0, -1.0, 1.0];
        let mut expected: Vec<f64> = q.to_vec();
        expected.extend(q.iter().map(|x| 0.5 * x));
        expected.extend([2.0, 1.0]);
        expected.extend([2.0, 1.0]);
        assert_eq!(out, expected);
        assert_eq!(map.width(), expected.len());
        // The constant, l alone and the filtered l alone.
        assert_eq!(map.directions(), vec![0, 6, 14]);
    }

    #[test]
    fn far_values_are_clipped() {
        let map = FeatureMap {
            center: vec![0.0],
            scale: vec![1.0],
            locus_scale: 1.0,
            embedded: 1,
            taus: None,
        };
        let mut out = Vec::new();
        map.features(&[100.0], 0.0, &[], &mut out);
        assert_eq!(out[1], CLIP);
        assert_eq!(out[2], CLIP * CLIP);
    }
}

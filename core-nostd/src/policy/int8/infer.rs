//! Running the network: quantising what the instrument knows into the network's inputs,
//! the fast layers of [`super::fast`] on a [`Dot`] backend ([`Fast`](super::Fast) unless
//! the caller picks one), and the planar reference kernels of [`super::kernels`] that the
//! fast path is tested against. Each decision is the argmax of the actor's int32 logits.

use super::*;

impl<'a> QuantizedPolicy<'a> {
    /// Quantises the side features of `input` (via a 432-byte `f32` buffer on the stack).
    pub fn quantize_side(&self, input: &PolicyInput<'_>, out: &mut [i8; SIDE_FEATURES]) {
        let mut f = [0.0f32; SIDE_FEATURES];
        input.write_side(&mut f);
        for (q, &v) in out.iter_mut().zip(f.iter()) {
            *q = quantize_value(v, self.side_input);
        }
    }

    /// One decision from what the instrument knows: quantise the inputs, run the network.
    pub fn decide(
        &self,
        input: &PolicyInput<'_>,
        scratch: &mut Scratch,
    ) -> Result<Decision, RunError> {
        let got = input.belief_planes();
        if got != self.rot_bins as usize {
            return Err(RunError::WrongRotBins {
                expected: self.rot_bins,
                got: got.min(255) as u8,
            });
        }
        let Scratch { belief, side, acts } = scratch;
        let p = self.belief_input;
        let k = self.rot_bins as usize;
        let x1 = &mut belief[..fast::padded_side(S1) * fast::padded_side(S1) * k];
        // The padding and any cell the grid lacks are real 0: the zero point.
        x1.fill(p.zero_point as i8);
        if input.write_belief_q_hwc(x1, p.scale, p.zero_point, fast::padded_side(S1)) == 0 {
            return Err(RunError::NotReady);
        }
        self.quantize_side(input, side);
        self.run::<Fast>(belief, side, acts)
    }

    /// One decision from already quantised inputs (`belief`: `K × 900`, `[plane][y][x]`).
    pub fn infer(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
        scratch: &mut Scratch,
    ) -> Result<Decision, RunError> {
        self.infer_with::<Fast>(belief, side, scratch)
    }

    /// [`QuantizedPolicy::infer`] on the inner products of backend `D` ([`dot::Portable`],
    /// or `dsp::Dsp` on the M4): what the self-test compares.
    pub fn infer_with<D: Dot>(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
        scratch: &mut Scratch,
    ) -> Result<Decision, RunError> {
        if belief.len() != self.belief_len() {
            return Err(RunError::BadInput);
        }
        let k = self.rot_bins as usize;
        let s = fast::padded_side(S1);
        let x1 = &mut scratch.belief[..s * s * k];
        x1.fill(self.belief_input.zero_point as i8);
        for (c, plane) in belief.chunks_exact(BELIEF_PLANE).enumerate() {
            for (y, row) in plane.chunks_exact(BELIEF_SIDE).enumerate() {
                for (x, &v) in row.iter().enumerate() {
                    x1[((y + 1) * s + x + 1) * k + c] = v;
                }
            }
        }
        self.run::<D>(&scratch.belief, side, &mut scratch.acts)
    }

    /// One decision from the inputs `scratch` already holds (the padded belief map and
    /// the side features), on backend `D`: for the self-test.
    pub(super) fn run_in<D: Dot>(&self, scratch: &mut Scratch) -> Result<Decision, RunError> {
        let Scratch { belief, side, acts } = scratch;
        self.run::<D>(belief, side, acts)
    }

    fn run<D: Dot>(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
        acts: &mut Activations,
    ) -> Result<Decision, RunError> {
        let l = &self.layers;
        let Activations { a2, cat, joint } = acts;
        let mut a1 = [0i8; fast::X2_LEN];
        let mut work = fast::ConvWork::new();
        let work = &mut work;
        // Architecture 2 uses a prefix of each buffer (sized for architecture 1).
        let len = |i: usize| l[i].dims.output_len();
        let a2 = a2.get_mut(..len(L_CONV2)).ok_or(RunError::BadInput)?;
        let h = len(L_BELIEF);
        let cat = cat.get_mut(..2 * h).ok_or(RunError::BadInput)?;
        let joint = joint.get_mut(..len(L_JOINT)).ok_or(RunError::BadInput)?;
        let s2 = fast::padded_side(S2);
        let a1p = a1.get_mut(..s2 * s2 * C1).ok_or(RunError::BadInput)?;
        fast::conv::<D>(&l[L_CONV1], belief, work, fast::ConvOut::Padded(a1p, s2));
        fast::conv::<D>(&l[L_CONV2], &a1[..], work, fast::ConvOut::Planar(a2));
        let (hb, hs) = cat.split_at_mut(h);
        fast::fully_connected_i8::<D>(&l[L_BELIEF], a2, hb);
        fast::fully_connected_i8::<D>(&l[L_SIDE], side, hs);
        fast::fully_connected_i8::<D>(&l[L_JOINT], cat, joint);
        let mut logits = [0i32; 3];
        fast::fully_connected_i32::<D>(&l[L_ACTOR], joint, &mut logits);
        let mut value = [0i32; 1];
        fast::fully_connected_i32::<D>(&l[L_CRITIC], joint, &mut value);
        Ok(Decision {
            action: ACTIONS[argmax(&logits)],
            logits,
            value: value[0],
        })
    }

    /// One decision by the reference kernels of [`kernels`] (planar layout, one product at
    /// a time, activations on the stack): what the fast path is tested against.
    #[inline(never)]
    pub fn infer_reference(
        &self,
        belief: &[i8],
        side: &[i8; SIDE_FEATURES],
    ) -> Result<Decision, RunError> {
        if belief.len() != self.belief_len() {
            return Err(RunError::BadInput);
        }
        let l = &self.layers;
        let len = |i: usize| l[i].dims.output_len();
        let mut a1 = [0i8; C1 * S1 * S1];
        let mut a2 = [0i8; FLAT];
        let mut cat = [0i8; 2 * HIDDEN];
        let mut joint = [0i8; HIDDEN];
        let a1 = a1.get_mut(..len(L_CONV1)).ok_or(RunError::BadInput)?;
        let a2 = a2.get_mut(..len(L_CONV2)).ok_or(RunError::BadInput)?;
        let h = len(L_BELIEF);
        let cat = cat.get_mut(..2 * h).ok_or(RunError::BadInput)?;
        let joint = joint.get_mut(..len(L_JOINT)).ok_or(RunError::BadInput)?;
        conv3x3_s2_p1(&l[L_CONV1], belief, a1);
        conv3x3_s2_p1(&l[L_CONV2], a1, a2);
        let (hb, hs) = cat.split_at_mut(h);
        fully_connected_i8(&l[L_BELIEF], a2, hb);
        fully_connected_i8(&l[L_SIDE], side, hs);
        fully_connected_i8(&l[L_JOINT], cat, joint);
        let mut logits = [0i32; 3];
        fully_connected_i32(&l[L_ACTOR], joint, &mut logits);
        let mut value = [0i32; 1];
        fully_connected_i32(&l[L_CRITIC], joint, &mut value);
        Ok(Decision {
            action: ACTIONS[argmax(&logits)],
            logits,
            value: value[0],
        })
    }
}

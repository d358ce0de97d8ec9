//! Standard normal draws for a group of lanes: lane `l` gets exactly the numbers
//! `rand_distr::StandardNormal` draws from lane `l`'s own [`NoiseRng`], four or eight lanes at a time.
//!
//! With AVX2 (AVX-512: eight lanes to a register, the edges gathered), the xoshiro256++ states live in vector registers and the ziggurat's common case
//! (one 64-bit word, a layer index, `u * x_i` accepted when `|u * x_i| < x_(i+1)`, about 98.5 % of
//! draws) runs on all lanes at once, with each lane's two layer edges loaded from the table together.
//! A lane that the fast case rejects is redrawn from its state before the draw by `rand_distr` itself
//! (the tail and wedge cases), so every lane stays on its scalar sequence. Without AVX2, every draw is the scalar
//! one. The scalar `rand_distr` call costs about 60 instructions a draw, the vector case about 8.

use rand::RngExt;
use rand_distr::StandardNormal;

use crate::engine::scenario::noise::NoiseRng;
#[cfg(target_arch = "x86_64")]
use crate::engine::scenario::noise::ZIG_NORM_X;
use crate::methods::detection_filter::kernel::{LANES, Lane, Vectors};

/// A lane group's noise generators advanced together; see the module docs.
#[derive(Debug, Clone)]
pub struct LaneNormals {
    /// `state[w][l]`: word `w` of lane `l`'s xoshiro256++ state.
    state: [[u64; LANES]; 4],
    vectors: Vectors,
}

impl LaneNormals {
    pub fn new(rngs: [NoiseRng; LANES]) -> Self {
        let states = rngs.map(|r| r.state());
        LaneNormals {
            state: std::array::from_fn(|w| std::array::from_fn(|l| states[l][w])),
            vectors: Vectors::current(),
        }
    }

    /// Fills each row of `out` with one draw per lane, rows in order.
    #[inline]
    pub fn fill(&mut self, out: &mut [Lane]) {
        #[cfg(target_arch = "x86_64")]
        match self.vectors {
            // SAFETY: `vectors` names a form only when the CPU has its features.
            Vectors::Avx512 => return unsafe { self.fill_avx512(out) },
            // SAFETY: as above.
            Vectors::Avx2 => return unsafe { self.fill_avx2(out) },
            Vectors::Scalar => {}
        }
        self.fill_scalar(out);
    }

    fn fill_scalar(&mut self, out: &mut [Lane]) {
        for l in 0..LANES {
            let mut rng = self.lane(l);
            for row in out.iter_mut() {
                row[l] = rng.sample(StandardNormal);
            }
            self.set_lane(l, &rng);
        }
    }

    fn lane(&self, l: usize) -> NoiseRng {
        NoiseRng::from_state(std::array::from_fn(|w| self.state[w][l]))
    }

    fn set_lane(&mut self, l: usize, rng: &NoiseRng) {
        for (w, word) in rng.state().into_iter().enumerate() {
            self.state[w][l] = word;
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn fill_avx2(&mut self, out: &mut [Lane]) {
        use std::arch::x86_64::*;

        // Four lanes per register (lanes 0-3, 4-7, ...), one register per state word.
        const QUARTETS: usize = LANES / 4;
        type Half = [__m256i; 4];
        let load = |w: &[u64; LANES], h: usize| -> __m256i {
            // SAFETY: 4 in-bounds words (h < LANES / 4); unaligned load.
            unsafe { _mm256_loadu_si256(w[4 * h..].as_ptr().cast()) }
        };
        let mut halves: [Half; QUARTETS] = std::array::from_fn(|h| std::array::from_fn(|w| load(&self.state[w], h)));
        let rotl23 = |x: __m256i| _mm256_or_si256(_mm256_slli_epi64::<23>(x), _mm256_srli_epi64::<41>(x));
        let rotl45 = |x: __m256i| _mm256_or_si256(_mm256_slli_epi64::<45>(x), _mm256_srli_epi64::<19>(x));
        let layer_mask = _mm256_set1_epi64x(0xff);
        let exponent_2 = _mm256_set1_epi64x(0x4000_0000_0000_0000);
        let three = _mm256_set1_pd(3.0);
        let sign = _mm256_set1_pd(-0.0);
        let edges = ZIG_NORM_X.as_ptr();

        for row in out.iter_mut() {
            let before = halves;
            let mut rejected = 0u32;
            for (h, half) in halves.iter_mut().enumerate() {
                let [s0, s1, s2, s3] = *half;
                let bits = _mm256_add_epi64(rotl23(_mm256_add_epi64(s0, s3)), s0);
                let t = _mm256_slli_epi64::<17>(s1);
                let s2 = _mm256_xor_si256(s2, s0);
                let s3 = _mm256_xor_si256(s3, s1);
                let s1 = _mm256_xor_si256(s1, s2);
                let s0 = _mm256_xor_si256(s0, s3);
                let s2 = _mm256_xor_si256(s2, t);
                *half = [s0, s1, s2, rotl45(s3)];

                // rand_distr: i = bits & 0xff; u = (bits >> 12 with exponent 1) - 3 in [-1, 1).
                let layer = _mm256_and_si256(bits, layer_mask);
                let u = _mm256_sub_pd(
                    _mm256_castsi256_pd(_mm256_or_si256(_mm256_srli_epi64::<12>(bits), exponent_2)),
                    three,
                );
                // Each lane's two edges `(x_i, x_(i+1))` are adjacent: one 2-wide load per lane, then
                // transposed, in place of two gathers (Zen 1's gathers took most of this loop's time).
                let (low, high) = (_mm256_castsi256_si128(layer), _mm256_extracti128_si256::<1>(layer));
                let at = |i: i64| -> __m128d {
                    // SAFETY: the layer `i` is at most 255, so `edges + i` and `edges + i + 1` are in the
                    // 257-entry table; unaligned load.
                    unsafe { _mm_loadu_pd(edges.add(i as usize)) }
                };
                let (p0, p1) = (at(_mm_cvtsi128_si64(low)), at(_mm_extract_epi64::<1>(low)));
                let (p2, p3) = (at(_mm_cvtsi128_si64(high)), at(_mm_extract_epi64::<1>(high)));
                let (even, odd) = (_mm256_set_m128d(p2, p0), _mm256_set_m128d(p3, p1));
                let (x_i, x_next) = (_mm256_unpacklo_pd(even, odd), _mm256_unpackhi_pd(even, odd));
                let x = _mm256_mul_pd(u, x_i);
                let accepted = _mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_andnot_pd(sign, x), x_next);
                rejected |= ((!_mm256_movemask_pd(accepted)) as u32 & 0xf) << (4 * h);
                // SAFETY: 4 in-bounds f64 of the row; unaligned store.
                unsafe { _mm256_storeu_pd(row[4 * h..].as_mut_ptr(), x) };
            }
            if rejected != 0 {
                let mut state = [[0u64; LANES]; 4];
                let store = |halves: &[Half; QUARTETS], state: &mut [[u64; LANES]; 4]| {
                    for (h, half) in halves.iter().enumerate() {
                        for (w, reg) in half.iter().enumerate() {
                            // SAFETY: 4 in-bounds words; unaligned store.
                            unsafe { _mm256_storeu_si256(state[w][4 * h..].as_mut_ptr().cast(), *reg) };
                        }
                    }
                };
                store(&before, &mut state);
                let mut after = [[0u64; LANES]; 4];
                store(&halves, &mut after);
                redraw(rejected, &state, &mut after, row);
                halves = std::array::from_fn(|h| std::array::from_fn(|w| load(&after[w], h)));
            }
        }
        for (h, half) in halves.iter().enumerate() {
            for (w, reg) in half.iter().enumerate() {
                // SAFETY: 4 in-bounds words; unaligned store.
                unsafe { _mm256_storeu_si256(self.state[w][4 * h..].as_mut_ptr().cast(), *reg) };
            }
        }
    }

    /// [`fill_avx2`](Self::fill_avx2)'s draws eight lanes to a register: the same integer and
    /// floating-point operations, with native rotates and the layer edges gathered.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn fill_avx512(&mut self, out: &mut [Lane]) {
        use std::arch::x86_64::*;

        const OCTETS: usize = LANES / 8;
        type Octet = [__m512i; 4];
        let load = |w: &[u64; LANES], h: usize| -> __m512i {
            // SAFETY: 8 in-bounds words (h < LANES / 8); unaligned load.
            unsafe { _mm512_loadu_si512(w[8 * h..].as_ptr().cast()) }
        };
        let mut octets: [Octet; OCTETS] = std::array::from_fn(|h| std::array::from_fn(|w| load(&self.state[w], h)));
        let layer_mask = _mm512_set1_epi64(0xff);
        let exponent_2 = _mm512_set1_epi64(0x4000_0000_0000_0000);
        let three = _mm512_set1_pd(3.0);
        let edges = ZIG_NORM_X.as_ptr();

        for row in out.iter_mut() {
            let before = octets;
            let mut rejected = 0u32;
            for (h, octet) in octets.iter_mut().enumerate() {
                let [s0, s1, s2, s3] = *octet;
                let bits = _mm512_add_epi64(_mm512_rol_epi64::<23>(_mm512_add_epi64(s0, s3)), s0);
                let t = _mm512_slli_epi64::<17>(s1);
                let s2 = _mm512_xor_si512(s2, s0);
                let s3 = _mm512_xor_si512(s3, s1);
                let s1 = _mm512_xor_si512(s1, s2);
                let s0 = _mm512_xor_si512(s0, s3);
                let s2 = _mm512_xor_si512(s2, t);
                *octet = [s0, s1, s2, _mm512_rol_epi64::<45>(s3)];

                let layer = _mm512_and_si512(bits, layer_mask);
                let u = _mm512_sub_pd(
                    _mm512_castsi512_pd(_mm512_or_si512(_mm512_srli_epi64::<12>(bits), exponent_2)),
                    three,
                );
                // SAFETY: every layer is at most 255, so `edges + layer` and `edges + layer + 1` are in
                // the 257-entry table.
                let (x_i, x_next) =
                    unsafe { (_mm512_i64gather_pd::<8>(layer, edges), _mm512_i64gather_pd::<8>(layer, edges.add(1))) };
                let x = _mm512_mul_pd(u, x_i);
                let accepted = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_abs_pd(x), x_next);
                rejected |= u32::from(!accepted) << (8 * h);
                // SAFETY: 8 in-bounds f64 of the row; unaligned store.
                unsafe { _mm512_storeu_pd(row[8 * h..].as_mut_ptr(), x) };
            }
            if rejected != 0 {
                let store = |octets: &[Octet; OCTETS]| {
                    let mut state = [[0u64; LANES]; 4];
                    for (h, octet) in octets.iter().enumerate() {
                        for (w, reg) in octet.iter().enumerate() {
                            // SAFETY: 8 in-bounds words; unaligned store.
                            unsafe { _mm512_storeu_si512(state[w][8 * h..].as_mut_ptr().cast(), *reg) };
                        }
                    }
                    state
                };
                let mut after = store(&octets);
                redraw(rejected, &store(&before), &mut after, row);
                octets = std::array::from_fn(|h| std::array::from_fn(|w| load(&after[w], h)));
            }
        }
        for (h, octet) in octets.iter().enumerate() {
            for (w, reg) in octet.iter().enumerate() {
                // SAFETY: 8 in-bounds words; unaligned store.
                unsafe { _mm512_storeu_si512(self.state[w][8 * h..].as_mut_ptr().cast(), *reg) };
            }
        }
    }
}

/// Lanes in the bit set `rejected` draw again from their states `before` the fast case, by
/// `rand_distr`; their draws go to `row` and their new states to `after`.
#[cold]
#[inline(never)]
fn redraw(rejected: u32, before: &[[u64; LANES]; 4], after: &mut [[u64; LANES]; 4], row: &mut Lane) {
    for l in (0..LANES).filter(|l| rejected & (1 << l) != 0) {
        let mut rng = NoiseRng::from_state(std::array::from_fn(|w| before[w][l]));
        row[l] = rng.sample(StandardNormal);
        for (w, word) in rng.state().into_iter().enumerate() {
            after[w][l] = word;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn lanes(seed: u64) -> [NoiseRng; LANES] {
        std::array::from_fn(|l| NoiseRng::seed_from_u64(seed * 100 + l as u64))
    }

    /// Both the vector and the scalar fill give each lane its own scalar sequence, including the
    /// rejected draws (about 1.5 % of draws, so thousands of them here) and ragged row counts.
    #[test]
    fn lanes_draw_exactly_rand_distr_per_lane() {
        let forms = [Vectors::Avx512, Vectors::Avx2, Vectors::Scalar];
        let cpu = forms.iter().position(|&v| v == Vectors::detect()).expect("one of them");
        // The CPU's own form and every narrower one.
        for &form in &forms[cpu..] {
            let mut group = LaneNormals::new(lanes(3));
            group.vectors = form;
            let mut reference = lanes(3);
            let mut rows = vec![[0.0; LANES]; 7];
            for block in 0..40_000 {
                let rows = &mut rows[..1 + block % 7];
                group.fill(rows);
                for row in rows.iter() {
                    for (l, rng) in reference.iter_mut().enumerate() {
                        let want: f64 = rng.sample(StandardNormal);
                        assert_eq!(row[l].to_bits(), want.to_bits(), "lane {l}, block {block}, {form:?}");
                    }
                }
            }
            for (l, rng) in reference.iter().enumerate() {
                assert_eq!(group.lane(l), *rng, "lane {l} state after the draws");
            }
        }
        println!("lane draws checked in the forms {:?} (this CPU's widest: {:?})", &forms[cpu..], forms[cpu]);
    }
}

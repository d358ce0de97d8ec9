//! The per-step arithmetic of linear plants and linear detection filters, shared by the one-trial
//! (general) path and the lane path that advances [`LANES`] trials at once, so that both do the same
//! floating-point operations in the same order and give bit-identical numbers.
//!
//! A product `out = base + M x` runs over a fixed [`Pattern`] of entries, row by row, each row
//! accumulated in increasing column order: `acc = base_i; acc = m_ij x_j + acc; ...; out_i = acc`
//! (`base` zero for `out = M x`). The pattern holds a
//! matrix's nonzeros when the matrix is the same in every trial of the study, and every entry when
//! parameter errors change it per trial: skipping the structural zeros halves the seed-000
//! arithmetic, and fixing the pattern per study (not per trial) keeps both paths on the same operations.
//! No fused multiply-add: Rust never contracts `a * b + c`, so the lanes (compiled for AVX2 when the
//! CPU has it) round exactly like the one-trial loop.

use nalgebra::DMatrix;

use crate::lti::{DiscreteLti, LtiPlant};
use crate::methods::detection_filter::filter::DetectionFilter;

/// Trials advanced together by the lane path.
pub const LANES: usize = 16;

/// One scalar quantity of every lane.
pub type Lane = [f64; LANES];

/// The widest vector instructions the CPU offers the lane path (every form gives the same numbers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Vectors {
    Avx512,
    Avx2,
    Scalar,
}

impl Vectors {
    /// This CPU's (the standard library caches the check).
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                return Vectors::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                return Vectors::Avx2;
            }
        }
        Vectors::Scalar
    }

    /// The form the lane loops and the lane draws run in on this thread: the CPU's widest, or the one
    /// [`with_form`] chose.
    pub fn current() -> Self {
        FORM.with(|f| f.get()).unwrap_or_else(Self::detect)
    }

    /// The forms this CPU runs: its widest and every narrower one (all give the same numbers).
    pub fn available() -> &'static [Vectors] {
        const ALL: [Vectors; 3] = [Vectors::Avx512, Vectors::Avx2, Vectors::Scalar];
        let widest = ALL.iter().position(|&v| v == Self::detect()).unwrap_or(ALL.len() - 1);
        &ALL[widest..]
    }
}

thread_local! {
    /// A form narrower than the CPU's, chosen by [`with_form`].
    static FORM: std::cell::Cell<Option<Vectors>> = const { std::cell::Cell::new(None) };
}

/// Runs `f` with this thread's lane loops and lane draws in `form`, one of [`Vectors::available`]: the
/// lane path is checked in every form the CPU has (`fdimc verify`, the tests).
///
/// # Panics
/// When the CPU lacks `form` (its instructions would be undefined behaviour).
pub fn with_form<T>(form: Vectors, f: impl FnOnce() -> T) -> T {
    assert!(Vectors::available().contains(&form), "this CPU does not run the {form:?} form");
    let before = FORM.with(|c| c.replace(Some(form)));
    let out = f();
    FORM.with(|c| c.set(before));
    out
}

/// Which entries of an `nrows x ncols` matrix a product visits, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Pattern {
    ncols: usize,
    /// Entries of row i are `cols[row_start[i]..row_start[i + 1]]`.
    row_start: Vec<usize>,
    cols: Vec<usize>,
}

impl Pattern {
    /// The nonzero entries of `m`.
    pub fn nonzeros(m: &DMatrix<f64>) -> Self {
        Self::build(m.nrows(), m.ncols(), |i, j| m[(i, j)] != 0.0)
    }

    /// Every entry of an `nrows x ncols` matrix.
    pub fn full(nrows: usize, ncols: usize) -> Self {
        Self::build(nrows, ncols, |_, _| true)
    }

    /// `full` when `m` changes from trial to trial, else its nonzeros.
    pub fn for_matrix(m: &DMatrix<f64>, varies_per_trial: bool) -> Self {
        if varies_per_trial { Self::full(m.nrows(), m.ncols()) } else { Self::nonzeros(m) }
    }

    fn build(nrows: usize, ncols: usize, keep: impl Fn(usize, usize) -> bool) -> Self {
        let mut row_start = vec![0];
        let mut cols = Vec::new();
        for i in 0..nrows {
            cols.extend((0..ncols).filter(|&j| keep(i, j)));
            row_start.push(cols.len());
        }
        Pattern { ncols, row_start, cols }
    }

    pub fn nrows(&self) -> usize {
        self.row_start.len() - 1
    }

    /// Entries visited per product.
    pub fn len(&self) -> usize {
        self.cols.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cols.is_empty()
    }
}

/// A number of one trial (`f64`) or one quantity of a group of lanes ([`Lane`]): what the products
/// multiply. Both do `acc = m x + acc` per trial, so the paths round alike.
pub trait Element: Copy + std::fmt::Debug {
    const ZERO: Self;
    /// Trials held: 1 or [`LANES`].
    const WIDTH: usize;
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self;
    fn mul_add(m: &Self, x: &Self, acc: &mut Self);
    /// [`Element::mul_add`] with the same coefficient `m` for every trial: the same operations.
    fn mul_add_shared(m: f64, x: &Self, acc: &mut Self);
    /// Equal bit for bit (a -0.0 coefficient is not a 0.0 one: the products' zeros would differ).
    fn same_bits(a: &Self, b: &Self) -> bool;
}

impl Element for f64 {
    const ZERO: Self = 0.0;
    const WIDTH: usize = 1;
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        f(0)
    }
    #[inline(always)]
    fn mul_add(m: &Self, x: &Self, acc: &mut Self) {
        *acc = m * x + *acc;
    }
    #[inline(always)]
    fn mul_add_shared(m: f64, x: &Self, acc: &mut Self) {
        *acc = m * x + *acc;
    }
    fn same_bits(a: &Self, b: &Self) -> bool {
        a.to_bits() == b.to_bits()
    }
}

impl Element for Lane {
    const ZERO: Self = [0.0; LANES];
    const WIDTH: usize = LANES;
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
        std::array::from_fn(f)
    }
    #[inline(always)]
    fn mul_add(m: &Self, x: &Self, acc: &mut Self) {
        for l in 0..LANES {
            acc[l] = m[l] * x[l] + acc[l];
        }
    }
    #[inline(always)]
    fn mul_add_shared(m: f64, x: &Self, acc: &mut Self) {
        for l in 0..LANES {
            acc[l] = m * x[l] + acc[l];
        }
    }
    fn same_bits(a: &Self, b: &Self) -> bool {
        a.iter().zip(b).all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

/// One block `sign * matrix(model)` of a stacked product, from column `offset` of the stacked vector.
struct Block<'p, M> {
    offset: usize,
    pattern: &'p Pattern,
    sign: f64,
    matrix: fn(&M) -> &DMatrix<f64>,
}

/// `y += [s_1 M_1 | s_2 M_2 | ...] v` over the blocks' patterns: the entries of row i in block order,
/// each block's in column order. One product over a stacked vector instead of one per block halves
/// the loop overhead of these small matrices and keeps the operation order of the blocks in turn.
#[derive(Debug, Clone)]
pub struct Product<E> {
    /// Row i's entries are `entries[row_end[i - 1]..row_end[i]]`.
    row_end: Vec<usize>,
    /// (index into the stacked vector, coefficient).
    entries: Vec<(usize, E)>,
    /// The entries with one coefficient each, when every trial of a lane group has the same ones (no
    /// per-trial model): the product then loads one number per entry instead of one per lane, the
    /// same operations otherwise. Idle lanes take the shared coefficients (their results are dropped).
    shared: Option<Vec<(usize, f64)>>,
}

impl<E: Element> Product<E> {
    /// `models` holds one model per trial of the element (`None`: an idle lane, zero coefficients).
    fn new<M>(nrows: usize, blocks: &[Block<'_, M>], models: &[Option<&M>]) -> Self {
        assert_eq!(models.len(), E::WIDTH, "one model per trial of the element");
        let mut row_end = Vec::with_capacity(nrows);
        let mut entries = Vec::new();
        // Per entry, the coefficient all models share (bit for bit), if they do.
        let mut shared = Vec::new();
        for i in 0..nrows {
            for b in blocks {
                assert_eq!(b.pattern.nrows(), nrows, "blocks of a product share their rows");
                for &j in &b.pattern.cols[b.pattern.row_start[i]..b.pattern.row_start[i + 1]] {
                    let of = |m: &M| b.sign * (b.matrix)(m)[(i, j)];
                    let value = E::from_fn(|l| models[l].map_or(0.0, of));
                    entries.push((b.offset + j, value));
                    // One trial per element has nothing to share.
                    if E::WIDTH > 1 {
                        let mut values = models.iter().flatten().map(|m| of(m));
                        let first = values.next();
                        let same = first.filter(|v| values.all(|w| w.to_bits() == v.to_bits()));
                        shared.push(same.map(|v| (b.offset + j, v)));
                    }
                }
            }
            row_end.push(entries.len());
        }
        let shared = (E::WIDTH > 1).then(|| shared.into_iter().collect::<Option<Vec<_>>>()).flatten();
        Product { row_end, entries, shared }
    }

    /// Does `other` do exactly the same operations on the same coefficients (bit for bit)?
    fn same_arithmetic(&self, other: &Self) -> bool {
        let same_shared = match (&self.shared, &other.shared) {
            (None, None) => true,
            (Some(a), Some(b)) => same_entries(a, b),
            _ => false,
        };
        self.row_end == other.row_end && same_entries(&self.entries, &other.entries) && same_shared
    }

    /// `out = M v` (accumulated from zero, see the module docs for the operation order).
    #[inline(always)]
    pub fn mul(&self, out: &mut [E], v: &[E]) {
        self.accumulate(out, v, |_| E::ZERO);
    }

    /// `out = base + M v` (accumulated onto `base`).
    #[inline(always)]
    pub fn mul_add(&self, out: &mut [E], base: &[E], v: &[E]) {
        self.accumulate(out, v, |i| base[i]);
    }

    /// Row i: `acc = start(i); acc = m_ij v_j + acc` over the row's entries; `out_i = acc`.
    /// Starting from a value instead of copying it into `out` first saves a memset or memcpy call
    /// per product.
    #[inline(always)]
    fn accumulate(&self, out: &mut [E], v: &[E], start: impl Fn(usize) -> E) {
        if let Some(shared) = &self.shared {
            return rows(&self.row_end, shared, out, v, start, |m, x, acc| E::mul_add_shared(*m, x, acc));
        }
        rows(&self.row_end, &self.entries, out, v, start, E::mul_add);
    }
}

/// The same (index, coefficient) entries, bit for bit.
fn same_entries<C: Element>(a: &[(usize, C)], b: &[(usize, C)]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|((i, x), (j, y))| i == j && C::same_bits(x, y))
}

/// Row i of `out`: `acc = start(i)`, then `mul_add(m, v_j, acc)` over the row's entries; `out_i = acc`.
#[inline(always)]
fn rows<E: Element, C>(
    row_end: &[usize],
    entries: &[(usize, C)],
    out: &mut [E],
    v: &[E],
    start: impl Fn(usize) -> E,
    mul_add: impl Fn(&C, &E, &mut E),
) {
    let mut first = 0;
    for (i, (out_i, &end)) in out.iter_mut().zip(row_end).enumerate() {
        let mut acc = start(i);
        for (j, m) in &entries[first..end] {
            mul_add(m, &v[*j], &mut acc);
        }
        *out_i = acc;
        first = end;
    }
}

/// Patterns of the true plant's matrices: `Ad`, `Bd` (full when parameter errors perturb the plant),
/// `C`, `D` and the output feedback `G` (never perturbed).
#[derive(Debug, Clone)]
pub struct PlantPatterns {
    ad: Pattern,
    bd: Pattern,
    c: Pattern,
    d: Pattern,
    g: Pattern,
}

impl PlantPatterns {
    pub fn new(nominal: &DiscreteLti, output_feedback: &DMatrix<f64>, varies_per_trial: bool) -> Self {
        PlantPatterns {
            ad: Pattern::for_matrix(&nominal.Ad, varies_per_trial),
            bd: Pattern::for_matrix(&nominal.Bd, varies_per_trial),
            c: Pattern::nonzeros(&nominal.C),
            d: Pattern::nonzeros(&nominal.D),
            g: Pattern::nonzeros(output_feedback),
        }
    }
}

/// Patterns of a detection filter's matrices: `Ad`, `Bd`, `Kd` (full when the design model is
/// perturbed per trial, or when the nominal design failed), `C`, `D` of the design model.
#[derive(Debug, Clone)]
pub struct FilterPatterns {
    ad: Pattern,
    bd: Pattern,
    k: Pattern,
    c: Pattern,
    d: Pattern,
}

impl FilterPatterns {
    pub fn new(design_plant: &LtiPlant, nominal: Option<&DetectionFilter>, varies_per_trial: bool) -> Self {
        let (n, m, p) = (design_plant.n_states(), design_plant.n_inputs(), design_plant.n_outputs());
        let of = |nominal: Option<&DMatrix<f64>>, rows, cols| match nominal {
            Some(a) if !varies_per_trial => Pattern::nonzeros(a),
            _ => Pattern::full(rows, cols),
        };
        FilterPatterns {
            ad: of(nominal.map(|f| &f.model.Ad), n, n),
            bd: of(nominal.map(|f| &f.model.Bd), n, m),
            k: of(nominal.map(|f| &f.discrete.K), n, p),
            c: Pattern::nonzeros(&design_plant.C),
            d: Pattern::nonzeros(&design_plant.D),
        }
    }
}

/// The true plant in the loop, for one trial ([`PlantStep`]) or a group of lanes ([`LanePlant`]):
///
/// ```text
/// y = C x + D r (+ noise, faults);   u = r - G y;   x <- Ad x + Bd u (+ process noise)
/// ```
///
/// on the stacked vector `[x; r; u]` of a [`PlantState`].
#[derive(Debug, Clone)]
pub struct Plant<E> {
    n: usize,
    nu: usize,
    /// `[C | D]` over `[x; r]`.
    measure: Product<E>,
    /// `-G` over `y`: `u = r - G y` accumulates onto `r`.
    feedback: Product<E>,
    /// `[Ad | 0 | Bd]` over `[x; r; u]`.
    advance: Product<E>,
}

pub type PlantStep = Plant<f64>;
pub type LanePlant = Plant<Lane>;

impl<E: Element> Plant<E> {
    /// One true plant per trial of the element (`None`: an idle lane).
    pub fn new(p: &PlantPatterns, truths: &[Option<&DiscreteLti>], output_feedback: &DMatrix<f64>) -> Self {
        let (n, nu, ny) = (p.ad.nrows(), p.bd.ncols, p.c.nrows());
        let block =
            |offset, pattern, matrix: fn(&DiscreteLti) -> &DMatrix<f64>| Block { offset, pattern, sign: 1.0, matrix };
        let feedback: Vec<Option<&DMatrix<f64>>> = truths.iter().map(|t| t.map(|_| output_feedback)).collect();
        Plant {
            n,
            nu,
            measure: Product::new(ny, &[block(0, &p.c, |t| &t.C), block(n, &p.d, |t| &t.D)], truths),
            feedback: Product::new(nu, &[Block { offset: 0, pattern: &p.g, sign: -1.0, matrix: |g| g }], &feedback),
            advance: Product::new(n, &[block(0, &p.ad, |t| &t.Ad), block(n + nu, &p.bd, |t| &t.Bd)], truths),
        }
    }

    /// The measured outputs before noise and faults: `y = C x + D r`.
    #[inline(always)]
    pub fn measure(&self, st: &PlantState<E>, y: &mut [E]) {
        self.measure.mul(y, &st.v[..self.n + self.nu]);
    }

    /// Closes the loop on the measured (noisy, possibly faulty) outputs: `u = r - G y`.
    #[inline(always)]
    pub fn close_loop(&self, st: &mut PlantState<E>, y: &[E]) {
        let (x_r, u) = st.v.split_at_mut(self.n + self.nu);
        self.feedback.mul_add(u, &x_r[self.n..], y);
    }

    /// `x <- Ad x + Bd u + w`, `w` added to the new state by `process_noise`.
    #[inline(always)]
    pub fn advance(&self, st: &mut PlantState<E>, process_noise: impl FnOnce(&mut [E])) {
        let x_next = &mut st.spare[..self.n];
        self.advance.mul(x_next, &st.v);
        process_noise(x_next);
        // `r` and `u` of the spare vector are stale; every step sets them before reading them.
        std::mem::swap(&mut st.v, &mut st.spare);
    }
}

/// The plant's stacked vector `[x; r; u]`, and a spare one the next state is written into.
#[derive(Debug, Clone)]
pub struct PlantState<E> {
    n: usize,
    nu: usize,
    v: Vec<E>,
    spare: Vec<E>,
}

impl<E: Element> PlantState<E> {
    pub fn new(x0: &[E], nu: usize) -> Self {
        let n = x0.len();
        let mut v = vec![E::ZERO; n + 2 * nu];
        v[..n].copy_from_slice(x0);
        PlantState { n, nu, spare: v.clone(), v }
    }

    /// The reference inputs `r`, set by the caller each step.
    pub fn reference_mut(&mut self) -> &mut [E] {
        &mut self.v[self.n..self.n + self.nu]
    }

    /// The reference inputs `r`, as set this step.
    pub fn reference(&self) -> &[E] {
        &self.v[self.n..self.n + self.nu]
    }

    /// The applied inputs `u` (after [`Plant::close_loop`]).
    pub fn inputs(&self) -> &[E] {
        &self.v[self.n + self.nu..]
    }

    /// The reference `r` and the inputs `u`, for a loop closed outside [`Plant::close_loop`] (a
    /// controller FMU).
    pub fn reference_and_inputs_mut(&mut self) -> (&[E], &mut [E]) {
        let (head, u) = self.v.split_at_mut(self.n + self.nu);
        (&head[self.n..], u)
    }
}

/// A detection filter, for one trial ([`FilterStep`]) or a group of lanes ([`LaneFilter`]):
///
/// ```text
/// gamma = y - C xhat - D u;   xhat <- Ad xhat + Bd u + Kd gamma
/// ```
///
/// on the stacked vector `[xhat; u; gamma]` of a [`FilterState`].
#[derive(Debug, Clone)]
pub struct Filter<E> {
    n: usize,
    nu: usize,
    /// `[-C | -D]` over `[xhat; u]`, accumulated onto `y`.
    residual: Product<E>,
    /// `[Ad | Bd | Kd]` over `[xhat; u; gamma]`.
    advance: Product<E>,
}

pub type FilterStep = Filter<f64>;
pub type LaneFilter = Filter<Lane>;

impl<E: Element> Filter<E> {
    /// One design per trial of the element (`None`: no design, or an idle lane).
    pub fn new(p: &FilterPatterns, designs: &[Option<&DetectionFilter>]) -> Self {
        let (n, nu, ny) = (p.ad.nrows(), p.bd.ncols, p.c.nrows());
        let block = |offset, pattern, sign, matrix: fn(&DetectionFilter) -> &DMatrix<f64>| Block {
            offset,
            pattern,
            sign,
            matrix,
        };
        Filter {
            n,
            nu,
            residual: Product::new(
                ny,
                &[block(0, &p.c, -1.0, |f| &f.model.C), block(n, &p.d, -1.0, |f| &f.model.D)],
                designs,
            ),
            advance: Product::new(
                n,
                &[
                    block(0, &p.ad, 1.0, |f| &f.model.Ad),
                    block(n, &p.bd, 1.0, |f| &f.model.Bd),
                    block(n + nu, &p.k, 1.0, |f| &f.discrete.K),
                ],
                designs,
            ),
        }
    }

    /// Does `other` compute the same residuals from the same inputs, bit for bit? Two detectors of a
    /// deck built on the same filter (a CUSUM on the seed filter beside the seed filter) then need
    /// one filter step per sample between them.
    pub fn same_arithmetic(&self, other: &Self) -> bool {
        (self.n, self.nu) == (other.n, other.nu)
            && self.residual.same_arithmetic(&other.residual)
            && self.advance.same_arithmetic(&other.advance)
    }

    /// Consumes sample k (`u(k)`, measured `y(k)`): sets the residual `gamma(k)` and advances the
    /// estimate. No allocation.
    #[inline(always)]
    pub fn step(&self, st: &mut FilterState<E>, u: &[E], y: &[E]) {
        let (n, nu) = (self.n, self.nu);
        st.z[n..n + nu].copy_from_slice(u);
        let (estimate_inputs, residual) = st.z.split_at_mut(n + nu);
        self.residual.mul_add(residual, y, estimate_inputs);
        self.advance.mul(&mut st.spare[..n], &st.z);
        // The spare vector's `u` and `gamma` are stale; every step sets them before reading them.
        std::mem::swap(&mut st.z, &mut st.spare);
    }
}

/// A filter's stacked vector `[xhat; u; gamma]`, and a spare one the next estimate is written into
/// (after a step, the spare holds that step's `u` and `gamma`).
#[derive(Debug, Clone)]
pub struct FilterState<E> {
    n: usize,
    nu: usize,
    z: Vec<E>,
    spare: Vec<E>,
}

impl<E: Element> FilterState<E> {
    pub fn new(x0: &[E], nu: usize, ny: usize) -> Self {
        let n = x0.len();
        let mut z = vec![E::ZERO; n + nu + ny];
        z[..n].copy_from_slice(x0);
        FilterState { n, nu, spare: z.clone(), z }
    }

    /// The prior estimate `xhat(k)` (before [`Filter::step`] consumes sample k).
    pub fn estimate(&self) -> &[E] {
        &self.z[..self.n]
    }

    /// The residual `gamma(k)` of the last step.
    pub fn residual(&self) -> &[E] {
        &self.spare[self.n + self.nu..]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    fn example() -> DMatrix<f64> {
        DMatrix::from_fn(6, 5, |i, j| {
            if (i + 2 * j) % 3 == 0 { 0.0 } else { ((i * 7 + j * 3) as f64).sin() * 10f64.powi(j as i32 - 2) }
        })
    }

    fn product<E: Element>(pattern: &Pattern, models: &[Option<&DMatrix<f64>>], sign: f64) -> Product<E> {
        Product::new(pattern.nrows(), &[Block { offset: 0, pattern, sign, matrix: |m| m }], models)
    }

    #[test]
    fn sparse_product_matches_the_dense_one_and_skips_only_zeros() {
        let m = example();
        let x = DVector::from_fn(5, |i, _| ((i + 1) as f64).cos() * 1e-3 + 0.1);
        let y0 = DVector::from_fn(6, |i, _| (i as f64 - 2.5) * 0.37);
        let want = &y0 - &m * &x;
        let nz = Pattern::nonzeros(&m);
        assert_eq!(nz.len(), m.iter().filter(|v| **v != 0.0).count());
        assert_eq!(Pattern::full(6, 5).len(), 30);
        for pattern in [nz, Pattern::full(6, 5)] {
            let mut got = y0.clone();
            product::<f64>(&pattern, &[Some(&m)], -1.0).mul_add(got.as_mut_slice(), y0.as_slice(), x.as_slice());
            assert!((got - &want).amax() < 1e-15);
        }
    }

    #[test]
    fn stacked_blocks_give_the_block_products_in_turn() {
        let (a, b) = (example(), example().map(|v| v * 0.5 - 1.0));
        let (pa, pb) = (Pattern::nonzeros(&a), Pattern::full(6, 5));
        let (xa, xb): (Vec<f64>, Vec<f64>) =
            ((0..5).map(|j| (j as f64).sin()).collect(), (0..5).map(|j| (j as f64).cos()).collect());
        let (mut after_a, mut want) = (vec![0.0; 6], vec![0.0; 6]);
        product::<f64>(&pa, &[Some(&a)], 1.0).mul_add(&mut after_a, &[0.25; 6], &xa);
        product::<f64>(&pb, &[Some(&b)], -1.0).mul_add(&mut want, &after_a, &xb);
        let blocks = [
            Block { offset: 0, pattern: &pa, sign: 1.0, matrix: |m: &(DMatrix<f64>, DMatrix<f64>)| &m.0 },
            Block { offset: 7, pattern: &pb, sign: -1.0, matrix: |m: &(DMatrix<f64>, DMatrix<f64>)| &m.1 },
        ];
        let stacked: Product<f64> = Product::new(6, &blocks, &[Some(&(a, b))]);
        let v: Vec<f64> = xa.iter().copied().chain([9.0, 9.0]).chain(xb.iter().copied()).collect();
        let mut got = vec![0.0; 6];
        stacked.mul_add(&mut got, &[0.25; 6], &v);
        assert_eq!(
            got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            want.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }

    /// One model for every lane (one idle): the product takes the shared coefficients, and each live lane
    /// rounds exactly like the one-trial product; different models per lane keep theirs.
    #[test]
    fn lanes_that_share_a_model_share_its_coefficients_and_round_alike() {
        let m = example();
        let pattern = Pattern::nonzeros(&m);
        let models: Vec<Option<&DMatrix<f64>>> = (0..LANES).map(|l| (l != 5).then_some(&m)).collect();
        let lanes = product::<Lane>(&pattern, &models, -1.0);
        assert_eq!(lanes.shared.as_ref().map(Vec::len), Some(pattern.len()));
        let other = m.map(|v| v * 1.5);
        let mixed: Vec<Option<&DMatrix<f64>>> = (0..LANES).map(|l| Some(if l == 2 { &other } else { &m })).collect();
        assert!(product::<Lane>(&pattern, &mixed, -1.0).shared.is_none());
        assert!(product::<f64>(&pattern, &[Some(&m)], -1.0).shared.is_none(), "one trial: nothing to share");

        let xs: Vec<Vec<f64>> = (0..LANES).map(|l| (0..5).map(|j| ((l * 5 + j) as f64).cos()).collect()).collect();
        let x_lanes: Vec<Lane> = (0..5).map(|j| std::array::from_fn(|l| xs[l][j])).collect();
        let base: Vec<Lane> = (0..6).map(|i| [0.3 - 0.1 * i as f64; LANES]).collect();
        let mut y_lanes = vec![[0.0; LANES]; 6];
        lanes.mul_add(&mut y_lanes, &base, &x_lanes);
        for (l, x) in xs.iter().enumerate().filter(|(l, _)| *l != 5) {
            let base: Vec<f64> = (0..6).map(|i| 0.3 - 0.1 * i as f64).collect();
            let mut y = vec![0.0; 6];
            product::<f64>(&pattern, &[Some(&m)], -1.0).mul_add(&mut y, &base, x);
            for i in 0..6 {
                assert_eq!(y_lanes[i][l].to_bits(), y[i].to_bits(), "lane {l} row {i}");
            }
        }
    }

    #[test]
    fn lanes_round_exactly_like_the_one_trial_product() {
        let base = example();
        let mats: Vec<DMatrix<f64>> = (0..LANES).map(|l| base.map(|v| v * (1.0 + 0.013 * l as f64))).collect();
        let pattern = Pattern::full(6, 5);
        let models: Vec<Option<&DMatrix<f64>>> = (0..LANES).map(|l| (l != 3).then(|| &mats[l])).collect();
        let lanes = product::<Lane>(&pattern, &models, 1.0);
        let xs: Vec<Vec<f64>> = (0..LANES).map(|l| (0..5).map(|j| ((l * 5 + j) as f64).sin()).collect()).collect();
        let x_lanes: Vec<Lane> = (0..5).map(|j| std::array::from_fn(|l| xs[l][j])).collect();
        let base: Vec<Lane> = (0..6).map(|i| [0.1 * i as f64; LANES]).collect();
        let mut y_lanes = vec![[0.0; LANES]; 6];
        lanes.mul_add(&mut y_lanes, &base, &x_lanes);
        for l in 0..LANES {
            let mut y: Vec<f64> = (0..6).map(|i| 0.1 * i as f64).collect();
            if l != 3 {
                let base = y.clone();
                product::<f64>(&pattern, &[Some(&mats[l])], 1.0).mul_add(&mut y, &base, &xs[l]);
            }
            for i in 0..6 {
                assert_eq!(y_lanes[i][l].to_bits(), y[i].to_bits(), "lane {l} row {i}");
            }
        }
    }
}

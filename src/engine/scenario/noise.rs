//! The per-step noise generator: xoshiro256++ (the algorithm of `rand::rngs::Xoshiro256PlusPlus`,
//! same outputs for the same seed) with its state open to the detection filters' lane path (8 generators in vector registers), which
//! runs eight of them side by side in vector registers and must hand a lane back to the scalar
//! generator when the ziggurat rejects.

use std::convert::Infallible;

use rand::{SeedableRng, TryRng};

/// xoshiro256++; see the module docs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NoiseRng {
    s: [u64; 4],
}

impl NoiseRng {
    pub(crate) fn state(&self) -> [u64; 4] {
        self.s
    }

    pub(crate) fn from_state(s: [u64; 4]) -> Self {
        debug_assert_ne!(s, [0; 4], "xoshiro's all-zero state is a fixed point");
        NoiseRng { s }
    }
}

impl TryRng for NoiseRng {
    type Error = Infallible;

    #[inline]
    fn try_next_u32(&mut self) -> Result<u32, Infallible> {
        // The low bits have linear dependencies; use the high ones (as rand does).
        self.try_next_u64().map(|v| (v >> 32) as u32)
    }

    #[inline]
    fn try_next_u64(&mut self) -> Result<u64, Infallible> {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        Ok(result)
    }

    fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Infallible> {
        for chunk in dst.chunks_mut(8) {
            let word = self.try_next_u64()?.to_le_bytes();
            chunk.copy_from_slice(&word[..chunk.len()]);
        }
        Ok(())
    }
}

impl SeedableRng for NoiseRng {
    type Seed = [u8; 32];

    /// The seed's four little-endian words; the all-zero seed (a fixed point) maps to
    /// `seed_from_u64(0)`, as in rand.
    fn from_seed(seed: [u8; 32]) -> Self {
        let s: [u64; 4] =
            std::array::from_fn(|w| u64::from_le_bytes(seed[8 * w..8 * w + 8].try_into().expect("8 bytes")));
        if s == [0; 4] {
            return Self::seed_from_u64(0);
        }
        NoiseRng { s }
    }

    /// SplitMix64 expansion, as in rand (never gives the all-zero state).
    fn seed_from_u64(mut state: u64) -> Self {
        const PHI: u64 = 0x9e37_79b9_7f4a_7c15;
        let s = std::array::from_fn(|_| {
            state = state.wrapping_add(PHI);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        });
        NoiseRng { s }
    }
}

/// The ziggurat's layer edges for the standard normal, `x_0 > x_1 > ... > x_256 = 0`: the table of
/// `rand_distr` 0.6 (`ziggurat_tables::ZIG_NORM_X`, MIT/Apache-2.0), which is not public there. Lane
/// draws accept `u * x_i` when `|u * x_i| < x_(i+1)`, exactly as `rand_distr::StandardNormal` does.
#[rustfmt::skip]
pub(crate) static ZIG_NORM_X: [f64; 257] =
    [3.910757959537090045, 3.654152885361008796, 3.449278298560964462, 3.320244733839166074,
     3.224575052047029100, 3.147889289517149969, 3.083526132001233044, 3.027837791768635434,
     2.978603279880844834, 2.934366867207854224, 2.894121053612348060, 2.857138730872132548,
     2.822877396825325125, 2.790921174000785765, 2.760944005278822555, 2.732685359042827056,
     2.705933656121858100, 2.680514643284522158, 2.656283037575502437, 2.633116393630324570,
     2.610910518487548515, 2.589575986706995181, 2.569035452680536569, 2.549221550323460761,
     2.530075232158516929, 2.511544441625342294, 2.493583041269680667, 2.476149939669143318,
     2.459208374333311298, 2.442725318198956774, 2.426670984935725972, 2.411018413899685520,
     2.395743119780480601, 2.380822795170626005, 2.366237056715818632, 2.351967227377659952,
     2.337996148795031370, 2.324308018869623016, 2.310888250599850036, 2.297723348901329565,
     2.284800802722946056, 2.272108990226823888, 2.259637095172217780, 2.247375032945807760,
     2.235313384928327984, 2.223443340090905718, 2.211756642882544366, 2.200245546609647995,
     2.188902771624720689, 2.177721467738641614, 2.166695180352645966, 2.155817819875063268,
     2.145083634046203613, 2.134487182844320152, 2.124023315687815661, 2.113687150684933957,
     2.103474055713146829, 2.093379631137050279, 2.083399693996551783, 2.073530263516978778,
     2.063767547809956415, 2.054107931648864849, 2.044547965215732788, 2.035084353727808715,
     2.025713947862032960, 2.016433734904371722, 2.007240830558684852, 1.998132471356564244,
     1.989106007615571325, 1.980158896898598364, 1.971288697931769640, 1.962493064942461896,
     1.953769742382734043, 1.945116560006753925, 1.936531428273758904, 1.928012334050718257,
     1.919557336591228847, 1.911164563769282232, 1.902832208548446369, 1.894558525668710081,
     1.886341828534776388, 1.878180486290977669, 1.870072921069236838, 1.862017605397632281,
     1.854013059758148119, 1.846057850283119750, 1.838150586580728607, 1.830289919680666566,
     1.822474540091783224, 1.814703175964167636, 1.806974591348693426, 1.799287584547580199,
     1.791640986550010028, 1.784033659547276329, 1.776464495522344977, 1.768932414909077933,
     1.761436365316706665, 1.753975320315455111, 1.746548278279492994, 1.739154261283669012,
     1.731792314050707216, 1.724461502945775715, 1.717160915015540690, 1.709889657069006086,
     1.702646854797613907, 1.695431651932238548, 1.688243209434858727, 1.681080704722823338,
     1.673943330923760353, 1.666830296159286684, 1.659740822855789499, 1.652674147080648526,
     1.645629517902360339, 1.638606196773111146, 1.631603456932422036, 1.624620582830568427,
     1.617656869570534228, 1.610711622367333673, 1.603784156023583041, 1.596873794420261339,
     1.589979870021648534, 1.583101723393471438, 1.576238702733332886, 1.569390163412534456,
     1.562555467528439657, 1.555733983466554893, 1.548925085471535512, 1.542128153226347553,
     1.535342571438843118, 1.528567729435024614, 1.521803020758293101, 1.515047842773992404,
     1.508301596278571965, 1.501563685112706548, 1.494833515777718391, 1.488110497054654369,
     1.481394039625375747, 1.474683555695025516, 1.467978458615230908, 1.461278162507407830,
     1.454582081885523293, 1.447889631277669675, 1.441200224845798017, 1.434513276002946425,
     1.427828197027290358, 1.421144398672323117, 1.414461289772464658, 1.407778276843371534,
     1.401094763676202559, 1.394410150925071257, 1.387723835686884621, 1.381035211072741964,
     1.374343665770030531, 1.367648583594317957, 1.360949343030101844, 1.354245316759430606,
     1.347535871177359290, 1.340820365893152122, 1.334098153216083604, 1.327368577624624679,
     1.320630975217730096, 1.313884673146868964, 1.307128989027353860, 1.300363230327433728,
     1.293586693733517645, 1.286798664489786415, 1.279998415710333237, 1.273185207661843732,
     1.266358287014688333, 1.259516886060144225, 1.252660221891297887, 1.245787495544997903,
     1.238897891102027415, 1.231990574742445110, 1.225064693752808020, 1.218119375481726552,
     1.211153726239911244, 1.204166830140560140, 1.197157747875585931, 1.190125515422801650,
     1.183069142678760732, 1.175987612011489825, 1.168879876726833800, 1.161744859441574240,
     1.154581450355851802, 1.147388505416733873, 1.140164844363995789, 1.132909248648336975,
     1.125620459211294389, 1.118297174115062909, 1.110938046009249502, 1.103541679420268151,
     1.096106627847603487, 1.088631390649514197, 1.081114409698889389, 1.073554065787871714,
     1.065948674757506653, 1.058296483326006454, 1.050595664586207123, 1.042844313139370538,
     1.035040439828605274, 1.027181966030751292, 1.019266717460529215, 1.011292417434978441,
     1.003256679539591412, 0.995156999629943084, 0.986990747093846266, 0.978755155288937750,
     0.970447311058864615, 0.962064143217605250, 0.953602409875572654, 0.945058684462571130,
     0.936429340280896860, 0.927710533396234771, 0.918898183643734989, 0.909987953490768997,
     0.900975224455174528, 0.891855070726792376, 0.882622229578910122, 0.873271068082494550,
     0.863795545546826915, 0.854189171001560554, 0.844444954902423661, 0.834555354079518752,
     0.824512208745288633, 0.814306670128064347, 0.803929116982664893, 0.793369058833152785,
     0.782615023299588763, 0.771654424216739354, 0.760473406422083165, 0.749056662009581653,
     0.737387211425838629, 0.725446140901303549, 0.713212285182022732, 0.700661841097584448,
     0.687767892786257717, 0.674499822827436479, 0.660822574234205984, 0.646695714884388928,
     0.632072236375024632, 0.616896989996235545, 0.601104617743940417, 0.584616766093722262,
     0.567338257040473026, 0.549151702313026790, 0.529909720646495108, 0.509423329585933393,
     0.487443966121754335, 0.463634336771763245, 0.437518402186662658, 0.408389134588000746,
     0.375121332850465727, 0.335737519180459465, 0.286174591747260509, 0.215241895913273806,
     0.000000000000000000];

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;
    use rand::rngs::Xoshiro256PlusPlus;

    #[test]
    fn same_outputs_as_rand_xoshiro256plusplus() {
        for seed in [[0u8; 32], [7u8; 32], std::array::from_fn(|i| (i as u8).wrapping_mul(37))] {
            let (mut ours, mut theirs) = (NoiseRng::from_seed(seed), Xoshiro256PlusPlus::from_seed(seed));
            for _ in 0..1000 {
                assert_eq!(ours.next_u64(), theirs.next_u64());
            }
        }
        let (mut ours, mut theirs) = (NoiseRng::seed_from_u64(42), Xoshiro256PlusPlus::seed_from_u64(42));
        assert_eq!(ours.next_u32(), theirs.next_u32());
        let (mut a, mut b) = ([0u8; 13], [0u8; 13]);
        ours.fill_bytes(&mut a);
        theirs.fill_bytes(&mut b);
        assert_eq!(a, b);
    }
}

/// A sensor channel's noise law, scaled so that its standard deviation is the deck's sigma.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorLaw {
    Gaussian,
    /// Student-t with `dof` > 2 degrees of freedom, scaled to unit variance: `z sqrt((dof - 2) / c)`,
    /// `z` the channel's standard normal draw and `c` an independent chi-square with `dof` degrees.
    StudentT {
        dof: f64,
    },
    /// The residual noise of a recorded log's channel ([`EmpiricalLaw`]).
    Empirical(std::sync::Arc<EmpiricalLaw>),
}

impl SensorLaw {
    /// `"gaussian"` or `"student_t(N)"`, N > 2 (the deck's words); or what is allowed.
    pub fn parse(text: &str) -> Result<SensorLaw, String> {
        if text == "gaussian" {
            return Ok(SensorLaw::Gaussian);
        }
        let dof = text
            .strip_prefix("student_t(")
            .and_then(|r| r.strip_suffix(')'))
            .and_then(|n| n.trim().parse::<f64>().ok());
        match dof {
            // The variance of a Student-t is dof / (dof - 2): finite above 2, so sigma is its spread.
            Some(dof) if dof.is_finite() && dof > 2.0 => Ok(SensorLaw::StudentT { dof }),
            Some(dof) => Err(format!("{text:?}: {dof} degrees of freedom; {ALLOWED_LAWS}")),
            None => Err(format!("{text:?}: {ALLOWED_LAWS}")),
        }
    }

    /// As the deck writes it.
    pub fn describe(&self) -> String {
        match self {
            SensorLaw::Gaussian => "gaussian".into(),
            SensorLaw::StudentT { dof } => format!("student_t({dof})"),
            SensorLaw::Empirical(law) => format!("empirical({})", law.source),
        }
    }
}

/// What `noise.sensor_law` allows, for messages.
pub const ALLOWED_LAWS: &str = "allowed \"gaussian\", \"student_t(N)\" with N > 2 degrees of freedom (e.g. \
     \"student_t(4)\"), or a recorded channel { log = \"FILE.ulg\", field = \"gyro_rad[1]\" } (topic and instance \
     optional: sensor_combined, 0)";

/// The least residuals a log's channel must give for an empirical law: its tail fit takes the largest
/// tenth, and needs at least [`crate::engine::stats::tail::MIN_EXCEEDANCES`] of them.
pub const MIN_EMPIRICAL_SAMPLES: usize = 500;

/// A channel's noise law taken from a recorded log: the residual of each sample about its four
/// neighbours, `e_k = x_k - (x_(k-2) + x_(k-1) + x_(k+1) + x_(k+2)) / 4` (slow motion cancels, the
/// sample's own noise dominates: for white noise `Var e = 1.25 sigma^2`), standardised to mean 0 and
/// variance 1 and taken as symmetric: `|X|` follows the residuals' `|e|` (linear between order
/// statistics) up to their largest tenth, and beyond it a generalised Pareto tail fitted to that
/// tenth, so draws reach past the largest value recorded. A fitted shape below 0 (a bounded tail) is
/// raised to 0, an exponential tail with the tenth's mean excess: a log of a few thousand samples
/// cannot tell a bounded tail from a Gaussian one (whose best fit at such a threshold is slightly
/// below 0, and which is not bounded), and a bounded law would put the one-in-10^11 sample that a
/// 1e-9 per hour figure turns on below a Gaussian's; the exponential tail is heavier than a
/// Gaussian's, so the law errs on the side of more false alarms. A draw maps the channel's standard
/// normal draw `z` through the quantiles, `sign(z) Q(P(|Z| > |z|))`, and uses no random number of
/// its own.
#[derive(Debug, Clone)]
pub struct EmpiricalLaw {
    /// Where it came from: `FILE: topic field`.
    pub source: String,
    /// The residuals' magnitudes, ascending.
    magnitudes: Vec<f64>,
    /// The tail beyond the largest tenth: its threshold (a magnitude), the share beyond it, and the
    /// generalised Pareto scale and shape (>= 0).
    tail_u: f64,
    tail_share: f64,
    tail_sigma: f64,
    tail_xi: f64,
    /// The shape the fit gave, before a negative one was raised to 0.
    fitted_xi: f64,
}

impl PartialEq for EmpiricalLaw {
    fn eq(&self, other: &Self) -> bool {
        self.source == other.source && self.magnitudes == other.magnitudes
    }
}

impl EmpiricalLaw {
    /// The law of a recorded channel's samples `x` (in time order); `source` names it in messages.
    pub fn from_samples(source: &str, x: &[f64]) -> Result<EmpiricalLaw, String> {
        let residuals: Vec<f64> =
            x.windows(5).map(|w| w[2] - (w[0] + w[1] + w[3] + w[4]) / 4.0).filter(|e| e.is_finite()).collect();
        if residuals.len() < MIN_EMPIRICAL_SAMPLES {
            return Err(format!(
                "{source}: {} residuals; an empirical law needs at least {MIN_EMPIRICAL_SAMPLES} (samples - 4)",
                residuals.len()
            ));
        }
        let n = residuals.len() as f64;
        let mean = residuals.iter().sum::<f64>() / n;
        let sd = (residuals.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        if !(sd > 0.0) {
            return Err(format!("{source}: the channel does not vary (its residuals are all equal)"));
        }
        let mut magnitudes: Vec<f64> = residuals.iter().map(|e| ((e - mean) / sd).abs()).collect();
        magnitudes.sort_by(f64::total_cmp);
        let k = magnitudes.len() / 10;
        let tail = crate::engine::stats::tail::TailFit::fit(&magnitudes, magnitudes.len() as u64, k)
            .ok_or_else(|| format!("{source}: its largest tenth of residuals is too tied to fit a tail"))?;
        // A shape of 1/2 or more has no finite variance, so no sigma could scale it.
        if !(tail.xi < 0.5) {
            return Err(format!(
                "{source}: its residuals' tail has shape {:.2} (generalised Pareto), too heavy for a finite \
                 variance; allowed below 0.5",
                tail.xi
            ));
        }
        let (tail_sigma, tail_xi) = if tail.xi >= 0.0 { (tail.sigma, tail.xi) } else { (tail.mean_excess(), 0.0) };
        Ok(EmpiricalLaw {
            source: source.to_string(),
            magnitudes,
            tail_u: tail.u,
            tail_share: tail.zeta(),
            tail_sigma,
            tail_xi,
            fitted_xi: tail.xi,
        })
    }

    /// The tail's shape as drawn (0 an exponential tail, above 0 a power law: a Student-t with `dof`
    /// degrees has `1 / dof`) and as fitted (below 0: bounded, raised to 0 for the draws).
    pub fn tail_shape(&self) -> (f64, f64) {
        (self.tail_xi, self.fitted_xi)
    }

    /// The residuals the law was made from.
    pub fn samples(&self) -> usize {
        self.magnitudes.len()
    }

    /// The draw that standard normal `z` maps to.
    #[inline]
    pub fn draw(&self, z: f64) -> f64 {
        // Two-sided survival of z, and the magnitude with that survival.
        let q = 2.0 * crate::engine::stats::intervals::normal_sf(z.abs());
        let magnitude = if q < self.tail_share {
            // The generalised Pareto excess whose survival beyond the threshold is q / share.
            let ln = (q / self.tail_share).ln();
            let excess = if self.tail_xi == 0.0 { -ln } else { (-self.tail_xi * ln).exp_m1() / self.tail_xi };
            self.tail_u + self.tail_sigma * excess
        } else {
            let m = self.magnitudes.len();
            let at = ((1.0 - q) * m as f64 - 0.5).clamp(0.0, (m - 1) as f64);
            let (i, frac) = (at.floor() as usize, at.fract());
            let next = self.magnitudes[(i + 1).min(m - 1)];
            self.magnitudes[i] + frac * (next - self.magnitudes[i])
        };
        magnitude.copysign(z)
    }
}

/// What makes a trial's standard normal sensor draws follow the channels' laws ([`SensorLaw`]): for a
/// Student-t channel a scale from a generator of its own (a trial's is
/// `crate::engine::scenario::streams::tail_scales`), per sample, channels in order, one chi-square
/// draw per Student-t channel; for an empirical channel its quantile map (no draw). The lane path and
/// the trial-at-a-time path draw the same numbers in the same order.
#[derive(Debug, Clone)]
pub struct TailScales {
    channels: Vec<Channel>,
    rng: NoiseRng,
}

#[derive(Debug, Clone)]
enum Channel {
    Gaussian,
    /// The chi-square law and `dof - 2`.
    StudentT(rand_distr::ChiSquared<f64>, f64),
    Empirical(std::sync::Arc<EmpiricalLaw>),
}

impl TailScales {
    /// The scales of `laws`' channels drawn from `rng` (a deck with a Student-t channel: a trial's
    /// are `crate::engine::scenario::streams::tail_scales`).
    pub fn new(laws: &[SensorLaw], rng: NoiseRng) -> TailScales {
        let channels = laws
            .iter()
            .map(|l| match l {
                SensorLaw::Gaussian => Channel::Gaussian,
                SensorLaw::StudentT { dof } => Channel::StudentT(
                    rand_distr::ChiSquared::new(*dof).expect("dof > 2, checked by the deck"),
                    dof - 2.0,
                ),
                SensorLaw::Empirical(law) => Channel::Empirical(law.clone()),
            })
            .collect();
        TailScales { channels, rng }
    }

    /// The factor channel `j`'s standard normal draw of this sample takes (1 for a channel that is
    /// not Student-t, which draws nothing).
    #[inline]
    pub fn scale(&mut self, j: usize) -> f64 {
        use rand::RngExt;
        match &self.channels[j] {
            Channel::StudentT(chi, excess) => (excess / self.rng.sample(chi)).sqrt(),
            _ => 1.0,
        }
    }

    /// Channel `j`'s draw of this sample from its standard normal draw `z`.
    #[inline]
    pub fn shape(&mut self, j: usize, z: f64) -> f64 {
        match &self.channels[j] {
            Channel::Empirical(law) => law.draw(z),
            _ => z * self.scale(j),
        }
    }

    /// Shapes one sample's standard normal draws, a draw per channel.
    #[inline]
    pub fn apply(&mut self, draws: &mut [f64]) {
        for (j, z) in draws.iter_mut().enumerate() {
            *z = self.shape(j, *z);
        }
    }
}

#[cfg(test)]
mod tail_tests {
    use super::*;

    /// Student-t(6) scaled to unit variance: variance 1 and the 0.999 quantile t(0.999; 6) sqrt(4/6)
    /// = 5.207626 x 0.816497 = 4.2520 (a Gaussian's: 3.090), from 400,000 draws; a Gaussian channel
    /// scales by 1.
    #[test]
    fn student_t_scales_give_unit_variance_and_the_t_quantile() {
        use rand::RngExt;
        let laws = [SensorLaw::Gaussian, SensorLaw::StudentT { dof: 6.0 }];
        let mut scales = TailScales::new(&laws, NoiseRng::seed_from_u64(7));
        let mut normals = NoiseRng::seed_from_u64(3);
        let n = 400_000;
        let mut x: Vec<f64> = (0..n)
            .map(|_| {
                assert_eq!(scales.scale(0), 1.0);
                normals.sample::<f64, _>(rand_distr::StandardNormal) * scales.scale(1)
            })
            .collect();
        let variance = x.iter().map(|v| v * v).sum::<f64>() / n as f64;
        assert!((variance - 1.0).abs() < 0.02, "variance {variance}");
        x.iter_mut().for_each(|v| *v = v.abs());
        x.sort_by(f64::total_cmp);
        // |x| at 0.998 is the two-sided 0.999 quantile.
        let q = x[(0.998 * n as f64) as usize];
        assert!((q / 4.2520 - 1.0).abs() < 0.03, "0.999 quantile {q}");
    }

    /// The empirical law of 20,000 Student-t(6) samples (unit variance; an excess kurtosis of 3), a
    /// slow swing of 50 standard deviations added that the neighbours' residual cancels: its draws
    /// have variance 1 (within 3 %) and the t's two-sided 0.999 quantile 4.252 (within 6 %, in the
    /// fitted tail); a Gaussian record's bounded fit is raised to an exponential tail, so a 6-sigma
    /// draw maps beyond 6; too short a record, or a constant one, is refused.
    #[test]
    fn an_empirical_law_keeps_a_record_s_tail_and_not_its_motion() {
        use rand::RngExt;
        let n = 20_000;
        let laws = [SensorLaw::StudentT { dof: 6.0 }];
        let mut scales = TailScales::new(&laws, NoiseRng::seed_from_u64(7));
        let mut normals = NoiseRng::seed_from_u64(3);
        let record: Vec<f64> = (0..n)
            .map(|k| {
                let z = normals.sample::<f64, _>(rand_distr::StandardNormal);
                50.0 * (k as f64 / 2000.0).sin() + scales.shape(0, z)
            })
            .collect();
        let law = EmpiricalLaw::from_samples("t6", &record).unwrap();
        assert_eq!(law.samples(), n - 4);
        assert!(law.tail_shape().0 > 0.0, "{:?}", law.tail_shape());
        let mut draws: Vec<f64> =
            (0..400_000).map(|_| law.draw(normals.sample::<f64, _>(rand_distr::StandardNormal))).collect();
        let variance = draws.iter().map(|v| v * v).sum::<f64>() / draws.len() as f64;
        assert!((variance - 1.0).abs() < 0.03, "variance {variance}");
        draws.iter_mut().for_each(|v| *v = v.abs());
        draws.sort_by(f64::total_cmp);
        let q = draws[(0.998 * draws.len() as f64) as usize];
        assert!((q / 4.2520 - 1.0).abs() < 0.06, "0.999 quantile {q}");
        let gaussian: Vec<f64> = (0..n).map(|_| normals.sample::<f64, _>(rand_distr::StandardNormal)).collect();
        let law = EmpiricalLaw::from_samples("gaussian", &gaussian).unwrap();
        let (drawn, fitted) = law.tail_shape();
        assert!(fitted < 0.0 && drawn == 0.0, "{fitted}");
        assert!(law.draw(6.0) > 6.0 && law.draw(6.0) < 12.0 && law.draw(-6.0) == -law.draw(6.0));
        let short = EmpiricalLaw::from_samples("short", &gaussian[..400]).unwrap_err();
        assert!(short.contains("396 residuals; an empirical law needs at least 500"), "{short}");
        assert!(EmpiricalLaw::from_samples("flat", &[1.0; 1000]).unwrap_err().contains("does not vary"));
    }

    #[test]
    fn laws_parse_as_the_deck_writes_them() {
        assert_eq!(SensorLaw::parse("gaussian"), Ok(SensorLaw::Gaussian));
        assert_eq!(SensorLaw::parse("student_t(4)"), Ok(SensorLaw::StudentT { dof: 4.0 }));
        assert_eq!(SensorLaw::parse("student_t( 2.5 )"), Ok(SensorLaw::StudentT { dof: 2.5 }));
        let err = SensorLaw::parse("student_t(2)").unwrap_err();
        assert!(err.starts_with("\"student_t(2)\": 2 degrees of freedom; allowed"), "{err}");
        assert!(SensorLaw::parse("cauchy").unwrap_err().contains("allowed \"gaussian\", \"student_t(N)\""));
    }
}

//! One-core floating-point throughput: independent multiply and add chains (no FMA), scalar, SSE2
//! 2-wide, AVX2 4-wide, and AVX2 FMA 4-wide, and the cost of the libm calls the models make. Flops: a
//! mul or an add = 1, an FMA = 2. The peaks the README's "How close to the limit" compares fdimc with.
//! Standalone (no dependencies); auto-vectorisation off so that the scalar kernels stay scalar:
//!
//! ```text
//! rustc --edition 2024 -C opt-level=3 -C codegen-units=1 -C llvm-args=-vectorize-loops=false \
//!     -C llvm-args=-vectorize-slp=false scripts/flop_rate.rs -o /tmp/flop_rate && /tmp/flop_rate
//! ```
use std::hint::black_box;
use std::time::Instant;

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

const ITERS: u64 = 50_000_000;

/// K independent (mul, add) pairs per iteration: p_i *= m; s_i += p_i. 2 K flops per iteration.
#[inline(never)]
fn scalar<const K: usize>(iters: u64) -> f64 {
    let m = black_box(1.0f64);
    let mut p = [0.0f64; K];
    let mut s = [0.0f64; K];
    for i in 0..K {
        p[i] = black_box(1.0 + i as f64 * 1e-3);
    }
    for _ in 0..iters {
        for i in 0..K {
            p[i] *= m;
            s[i] += p[i];
        }
    }
    s.iter().sum::<f64>() + p.iter().sum::<f64>()
}

#[inline(never)]
fn sse2<const K: usize>(iters: u64) -> f64 {
    unsafe {
        let m = _mm_set1_pd(black_box(1.0));
        let mut p = [_mm_set1_pd(black_box(1.0)); K];
        let mut s = [_mm_setzero_pd(); K];
        for _ in 0..iters {
            for i in 0..K {
                p[i] = _mm_mul_pd(p[i], m);
                s[i] = _mm_add_pd(s[i], p[i]);
            }
        }
        let mut out = [0.0; 2];
        let mut t = _mm_setzero_pd();
        for i in 0..K {
            t = _mm_add_pd(t, _mm_add_pd(s[i], p[i]));
        }
        _mm_storeu_pd(out.as_mut_ptr(), t);
        out[0] + out[1]
    }
}

#[target_feature(enable = "avx2")]
fn avx2<const K: usize>(iters: u64) -> f64 {
    let m = _mm256_set1_pd(black_box(1.0));
    let mut p = [_mm256_set1_pd(black_box(1.0)); K];
    let mut s = [_mm256_setzero_pd(); K];
    for _ in 0..iters {
        for i in 0..K {
            p[i] = _mm256_mul_pd(p[i], m);
            s[i] = _mm256_add_pd(s[i], p[i]);
        }
    }
    sum_lanes(&s) + sum_lanes(&p)
}

/// The sum of every lane of `v` (the kernels return it so that their work is not optimised away).
#[target_feature(enable = "avx2")]
fn sum_lanes(v: &[__m256d]) -> f64 {
    let mut t = _mm256_setzero_pd();
    for &x in v {
        t = _mm256_add_pd(t, x);
    }
    let mut out = [0.0; 4];
    unsafe { _mm256_storeu_pd(out.as_mut_ptr(), t) };
    out.iter().sum()
}

/// K independent FMA chains: a_i = a_i * m + c. 8 flops per FMA.
#[target_feature(enable = "avx2,fma")]
fn fma<const K: usize>(iters: u64) -> f64 {
    let m = _mm256_set1_pd(black_box(1.0));
    let c = _mm256_set1_pd(black_box(1e-9));
    let mut a = [_mm256_setzero_pd(); K];
    for _ in 0..iters {
        for i in 0..K {
            a[i] = _mm256_fmadd_pd(a[i], m, c);
        }
    }
    sum_lanes(&a)
}

/// K independent chains a_i = a_i * m + c (separate mul then add, no FMA): 2 K flops per iteration,
/// K + 2 registers, so K = 12 fits the 16 vector registers without spilling.
#[inline(never)]
fn scalar_chain<const K: usize>(iters: u64) -> f64 {
    let m = black_box(1.0f64);
    let c = black_box(1e-9f64);
    let mut a = [0.0f64; K];
    for _ in 0..iters {
        for i in 0..K {
            a[i] = a[i] * m + c;
        }
    }
    a.iter().sum()
}

#[inline(never)]
fn sse2_chain<const K: usize>(iters: u64) -> f64 {
    unsafe {
        let m = _mm_set1_pd(black_box(1.0));
        let c = _mm_set1_pd(black_box(1e-9));
        let mut a = [_mm_setzero_pd(); K];
        for _ in 0..iters {
            for i in 0..K {
                a[i] = _mm_add_pd(_mm_mul_pd(a[i], m), c);
            }
        }
        let mut t = _mm_setzero_pd();
        for i in 0..K {
            t = _mm_add_pd(t, a[i]);
        }
        _mm_cvtsd_f64(t)
    }
}

#[target_feature(enable = "avx2")]
fn avx2_chain<const K: usize>(iters: u64) -> f64 {
    let m = _mm256_set1_pd(black_box(1.0));
    let c = _mm256_set1_pd(black_box(1e-9));
    let mut a = [_mm256_setzero_pd(); K];
    for _ in 0..iters {
        for i in 0..K {
            a[i] = _mm256_add_pd(_mm256_mul_pd(a[i], m), c);
        }
    }
    sum_lanes(&a)
}

/// One dependent add chain: iterations per second times the add latency is the clock.
#[inline(never)]
fn latency(iters: u64) -> f64 {
    let c = black_box(1e-9);
    let mut s = 0.0f64;
    for _ in 0..iters {
        s += c;
    }
    s
}

fn time(name: &str, flops_per_iter: f64, iters: u64, f: impl Fn(u64) -> f64) -> f64 {
    let mut best = 0.0f64;
    let mut runs = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        let r = f(black_box(iters));
        let s = t.elapsed().as_secs_f64();
        black_box(r);
        let g = flops_per_iter * iters as f64 / s / 1e9;
        runs.push(format!("{g:.2}"));
        best = best.max(g);
    }
    println!("{name:<34} runs [{}] GFlop/s, best {best:.2}", runs.join(", "));
    best
}

/// ns per call of a libm function over 4096 varied arguments (independent calls: throughput).
fn libm(name: &str, f: impl Fn(f64) -> f64, lo: f64, hi: f64) {
    let xs: Vec<f64> = (0..4096).map(|i| lo + (hi - lo) * (i as f64 + 0.5) / 4096.0).collect();
    let reps = 1000;
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        let mut acc = 0.0;
        for _ in 0..reps {
            for &x in black_box(&xs) {
                acc += f(x);
            }
        }
        black_box(acc);
        best = best.min(t.elapsed().as_secs_f64() / (reps * xs.len()) as f64 * 1e9);
    }
    println!("{name:<34} best of 3: {best:.1} ns/call");
}

fn main() {
    let which = std::env::args().nth(1).unwrap_or_default();
    let all = which.is_empty();
    if all || which == "scalar" {
        time("scalar mul+add, K=6", 12.0, ITERS, scalar::<6>);
    }
    if all || which == "scalar" {
        time("scalar mul->add chains, K=12", 24.0, ITERS / 2, scalar_chain::<12>);
        time("scalar mul->add chains, K=14", 28.0, ITERS / 2, scalar_chain::<14>);
        let g = time("dependent add chain (1 flop/iter)", 1.0, ITERS * 2, latency);
        println!("  -> clock estimate {:.2} GHz if the add latency is 3 cycles (Zen 1; our assumption)", 3.0 * g);
    }
    if all || which == "sse2" {
        time("SSE2 2-wide mul->add chains, K=12", 48.0, ITERS / 4, sse2_chain::<12>);
        time("SSE2 2-wide mul->add chains, K=14", 56.0, ITERS / 4, sse2_chain::<14>);
        time("SSE2 2-wide mul+add, K=6", 24.0, ITERS / 2, sse2::<6>);
    }
    if all || which == "libm" {
        libm("sin_cos (sum of both)", |x| { let (s, c) = x.sin_cos(); s + c }, -1.0, 1.0);
        libm("exp", f64::exp, -3.0, 3.0);
        libm("sqrt", f64::sqrt, 0.1, 100.0);
        libm("atan2(x, 0.7)", |x| x.atan2(0.7), -1.0, 1.0);
        libm("asin", f64::asin, -0.9, 0.9);
        libm("ln", f64::ln, 0.1, 10.0);
        libm("tan", f64::tan, -1.0, 1.0);
    }
    if is_x86_feature_detected!("avx2") && (all || which == "avx2") {
        time("AVX2 4-wide mul+add, K=4", 32.0, ITERS / 4, |n| unsafe { avx2::<4>(n) });
        time("AVX2 4-wide mul+add, K=6", 48.0, ITERS / 4, |n| unsafe { avx2::<6>(n) });
        time("AVX2 4-wide mul->add chains, K=12", 96.0, ITERS / 8, |n| unsafe { avx2_chain::<12>(n) });
    }
    if is_x86_feature_detected!("fma") && (all || which == "fma") {
        time("AVX2 FMA 4-wide, K=8", 64.0, ITERS / 4, |n| unsafe { fma::<8>(n) });
        time("AVX2 FMA 4-wide, K=12", 96.0, ITERS / 4, |n| unsafe { fma::<12>(n) });
    }
}

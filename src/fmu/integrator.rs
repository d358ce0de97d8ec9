//! The fixed-step integrator fdimc steps a model-exchange FMU with: classical Runge-Kutta 4 on slices,
//! for a right-hand side that may fail (an FMU call). Its arithmetic is the one of
//! `methods::thrust_loss::vehicle::rk4` and `vehicles::aerosonde::step_rk4` element by element, so the
//! same equations written in Rust and stepped by it give the same bits.

/// Work space for one state size.
#[derive(Debug, Clone)]
pub struct Rk4 {
    k: [Vec<f64>; 4],
    stage: Vec<f64>,
}

impl Rk4 {
    pub fn new(n: usize) -> Self {
        Rk4 { k: std::array::from_fn(|_| vec![0.0; n]), stage: vec![0.0; n] }
    }

    /// `x <- x(t_s + dt_s)` for `x' = f(t, x)`; `f(t, x, dx)` writes the derivative into `dx`.
    pub fn step<E>(
        &mut self,
        x: &mut [f64],
        t_s: f64,
        dt_s: f64,
        mut f: impl FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
    ) -> Result<(), E> {
        let [k1, k2, k3, k4] = &mut self.k;
        let stage = &mut self.stage;
        f(t_s, x, k1)?;
        for i in 0..x.len() {
            stage[i] = x[i] + k1[i] * (dt_s / 2.0);
        }
        f(t_s + dt_s / 2.0, stage, k2)?;
        for i in 0..x.len() {
            stage[i] = x[i] + k2[i] * (dt_s / 2.0);
        }
        f(t_s + dt_s / 2.0, stage, k3)?;
        for i in 0..x.len() {
            stage[i] = x[i] + k3[i] * dt_s;
        }
        f(t_s + dt_s, stage, k4)?;
        for i in 0..x.len() {
            x[i] = x[i] + (k1[i] + k2[i] * 2.0 + k3[i] * 2.0 + k4[i]) * (dt_s / 6.0);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SVector;

    #[test]
    fn same_bits_as_the_vehicles_rk4_on_a_nonlinear_system() {
        let f = |t: f64, x: &SVector<f64, 2>| SVector::<f64, 2>::new(x[1], -x[0].sin() - 0.3 * x[1] + t.cos());
        let mut a = SVector::<f64, 2>::new(0.7, -0.2);
        let mut b = [0.7, -0.2];
        let mut rk = Rk4::new(2);
        for k in 0..100 {
            let t = k as f64 * 0.01;
            a = crate::methods::thrust_loss::vehicle::rk4(&a, t, 0.01, f);
            rk.step::<()>(&mut b, t, 0.01, |t, x, dx| {
                let d = f(t, &SVector::<f64, 2>::new(x[0], x[1]));
                dx.copy_from_slice(d.as_slice());
                Ok(())
            })
            .unwrap();
        }
        assert_eq!(a.as_slice(), &b);
        // The pendulum moved: a test of an integrator that did nothing would fail here.
        assert!((b[0] - 0.7).abs() > 0.03 && b[1] > 0.0, "{b:?}");
    }

    /// Against closed forms, not another copy of RK4: on `x' = lambda x` one step multiplies by the
    /// fourth-order Taylor polynomial of `z = lambda dt` exactly (to rounding); on `x'' = -x + cos(2t)`
    /// (exact solution `x = (4 cos t - cos 2t) / 3` from `x = 1, x' = 0`) the error at t = 2 falls
    /// 16-fold as the step halves (fourth order), and a step of 0.05 is within 1e-6.
    #[test]
    fn one_step_is_the_taylor_polynomial_and_the_error_falls_at_fourth_order() {
        let (lambda, dt) = (-3.0, 0.1);
        let z: f64 = lambda * dt;
        let growth = 1.0 + z + z * z / 2.0 + z.powi(3) / 6.0 + z.powi(4) / 24.0;
        let mut x = [1.0];
        let mut rk = Rk4::new(1);
        for k in 0..10 {
            rk.step::<()>(&mut x, k as f64 * dt, dt, |_, x, dx| {
                dx[0] = lambda * x[0];
                Ok(())
            })
            .unwrap();
        }
        assert!((x[0] / growth.powi(10) - 1.0).abs() < 1e-13, "{} against {}", x[0], growth.powi(10));
        let error_at_two = |dt: f64| {
            let mut x = [1.0, 0.0];
            let mut rk = Rk4::new(2);
            let steps = (2.0 / dt).round() as usize;
            for k in 0..steps {
                rk.step::<()>(&mut x, k as f64 * dt, dt, |t, x, dx| {
                    dx[0] = x[1];
                    dx[1] = -x[0] + (2.0 * t).cos();
                    Ok(())
                })
                .unwrap();
            }
            (x[0] - (4.0 * 2f64.cos() - 4f64.cos()) / 3.0).abs()
        };
        let (coarse, fine) = (error_at_two(0.1), error_at_two(0.05));
        assert!((14.0..18.0).contains(&(coarse / fine)), "errors {coarse:e} and {fine:e}: ratio {}", coarse / fine);
        assert!(fine < 1e-6, "{fine:e}");
    }
}

//! Accuracy knobs: every approximation of a bake has a setting, and
//! `rothray bench SCENE --knob K` measures run time against error along it
//! (the README gives each curve and why each default sits where it does).

/// One approximation's setting (`None` = its default). Set
/// [`crate::RenderScene::knobs`] before baking.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Knobs {
    /// Swept-sphere root tolerance, relative to the shape's size.
    pub sweep: Option<f32>,
    /// Generalized-cylinder marching and bisection tolerance, relative to the
    /// shape's size (frame samples stay at the scene tolerance's).
    pub gcyl: Option<f32>,
    /// Rotation-minimizing (and Frenet) frame samples per segment.
    pub frame: Option<u32>,
    /// Torus root polish tolerance, relative to its minor radius (0: full f64;
    /// `None`: [`rothray_primitives::kernels::TORUS_TOLERANCE`]).
    pub torus: Option<f32>,
    /// Mesh winding number far-field acceptance ratio (node radii; infinity:
    /// the exact sum).
    pub winding: Option<f32>,
    /// CSG fusing tolerance, relative to the scene's size (and, times 0.2, to
    /// the ray origin's distance from the scene).
    pub fuse: Option<f32>,
}

/// The named knobs of `rothray bench --knob`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Knob {
    /// [`Knobs::sweep`].
    Sweep,
    /// [`Knobs::gcyl`].
    Gcyl,
    /// [`Knobs::frame`].
    Frame,
    /// [`Knobs::torus`].
    Torus,
    /// [`Knobs::winding`].
    Winding,
    /// [`Knobs::fuse`].
    Fuse,
}

impl Knob {
    /// Every knob, in the README's order.
    pub const ALL: [Knob; 6] = [Knob::Sweep, Knob::Gcyl, Knob::Frame, Knob::Torus, Knob::Winding, Knob::Fuse];

    /// The name `--knob` takes.
    pub fn name(self) -> &'static str {
        match self {
            Knob::Sweep => "sweep",
            Knob::Gcyl => "gcyl",
            Knob::Frame => "frame",
            Knob::Torus => "torus",
            Knob::Winding => "winding",
            Knob::Fuse => "fuse",
        }
    }

    /// The knob named `s`.
    pub fn parse(s: &str) -> Option<Knob> {
        Knob::ALL.into_iter().find(|k| k.name() == s)
    }

    /// What the setting means (for tables and plots).
    pub fn unit(self) -> &'static str {
        match self {
            Knob::Sweep | Knob::Gcyl => "tolerance / size",
            Knob::Frame => "samples per segment",
            Knob::Torus => "polish tolerance / minor radius",
            Knob::Winding => "far-field ratio (node radii)",
            Knob::Fuse => "fusing tolerance / scene size",
        }
    }

    /// The default range of `bench --knob`, coarsest first.
    pub fn range(self) -> &'static [f64] {
        match self {
            Knob::Sweep | Knob::Gcyl => &[1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8],
            Knob::Frame => &[2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0],
            Knob::Torus => &[1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-7, 1e-8, 1e-10, 0.0],
            Knob::Winding => &[1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 10.0],
            Knob::Fuse => &[1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7],
        }
    }

    /// The setting errors are measured against: the finest the knob allows.
    pub fn reference(self) -> f64 {
        match self {
            Knob::Sweep | Knob::Gcyl => 1e-12,
            Knob::Frame => 4096.0,
            Knob::Torus => 0.0,
            Knob::Winding => f64::INFINITY,
            Knob::Fuse => 1e-8,
        }
    }

    /// Checks a setting; the message states the accepted range.
    pub fn check(self, v: f64) -> Result<(), String> {
        let ok = match self {
            Knob::Sweep | Knob::Gcyl => v > 0.0 && v <= 1e-2,
            Knob::Frame => v.fract() == 0.0 && (2.0..=65536.0).contains(&v),
            Knob::Torus => (0.0..=1.0).contains(&v),
            Knob::Winding => v >= 1.0,
            Knob::Fuse => v > 0.0 && v <= 0.1,
        };
        let range = match self {
            Knob::Sweep | Knob::Gcyl => "(0, 1e-2]",
            Knob::Frame => "a whole number from 2 to 65536",
            Knob::Torus => "[0, 1]",
            Knob::Winding => "[1, inf]",
            Knob::Fuse => "(0, 0.1]",
        };
        if ok {
            Ok(())
        } else {
            Err(format!("knob {}: {v} is out of range; it takes {range}", self.name()))
        }
    }

    /// `knobs` with this knob at `v` (checked with [`Knob::check`] first).
    pub fn set(self, knobs: Knobs, v: f64) -> Knobs {
        let v32 = v as f32;
        match self {
            Knob::Sweep => Knobs { sweep: Some(v32), ..knobs },
            Knob::Gcyl => Knobs { gcyl: Some(v32), ..knobs },
            Knob::Frame => Knobs { frame: Some(v as u32), ..knobs },
            Knob::Torus => Knobs { torus: Some(v32), ..knobs },
            Knob::Winding => Knobs { winding: Some(v32), ..knobs },
            Knob::Fuse => Knobs { fuse: Some(v32), ..knobs },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_valid_and_coarsest_first() {
        for k in Knob::ALL {
            assert_eq!(Knob::parse(k.name()), Some(k));
            assert!(k.range().len() >= 5, "{k:?}");
            assert!(k.check(k.reference()).is_ok(), "{k:?}");
            for v in k.range() {
                assert!(k.check(*v).is_ok(), "{k:?} {v}");
            }
        }
        assert!(Knob::Frame.check(1.5).unwrap_err().contains("2 to 65536"));
    }
}

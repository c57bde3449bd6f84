//! Calibration: measurements as a training signal (the paper's future work, Sec. 7; issue 57).
//!
//! For a fixed set of traced paths a link's gain Σ |a_p|² is a smooth function of what a twin
//! leaves uncertain: each material's permittivity and conductivity (through the slab
//! coefficients of every reflection and transmission on a path), the foliage loss rate (through
//! the metres a path runs in canopies) and a per-cell offset. So the paths are traced once, each
//! is kept as the interactions it makes ([`PathReplay`]), and a fit moves the parameters by
//! replaying them: no ray is cast. Derivatives are analytic: the slab coefficients' in η
//! ([`em::slab_derivative`]) carried forward through each path's field, which is linear in
//! every coefficient. The fit is Levenberg-Marquardt on the training links' path loss, with
//! Gaussian priors at the ITU-R P.2040 values in log space and bounds round them.
//!
//! Paths through an edge (diffraction) keep their traced power, and diffusely scattered power
//! moves only with the scattering coefficient: a material moves them too, through the wedge
//! faces' reflection and the scattering surface, and that is left out here (the share they
//! carry is small where specular paths exist). An antenna's height moves the specular paths by
//! the image method; the rest waits for a retrace (the Calibrate stage).

use glam::DVec3;
use num_complex::Complex64 as C64;
use serde::{Deserialize, Serialize};

use super::antenna::Antenna;
use super::em::{complex_permittivity, eps_sigma_of, slab, slab_derivative};
use super::field::{self, CVec};
use super::foliage::FoliageLoss;
use super::path::{InteractionKind, LinkPaths, Path, TraceOptions};
use super::scene::RfScene;
use crate::artifact::Material;

/// A parameter a calibration can move.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Parameter {
    /// The real relative permittivity ε' of a material (fitted as ln ε').
    Permittivity(Material),
    /// The conductivity σ of a material, S/m (fitted as ln σ).
    Conductivity(Material),
    /// The foliage loss rate, dB/m (the linear law's).
    FoliageDbPerM,
    /// The scattering coefficient S of every surface (effective roughness: specular reflection
    /// keeps √(1 − S²) of the field, diffuse scattering takes S²), fitted as ln S.
    Scattering,
    /// A cell's transmit antenna tilt, as an offset in degrees (the fit's cell index).
    Tilt(u32),
    /// A cell's transmit antenna bearing, as an offset in degrees (the fit's cell index).
    Azimuth(u32),
    /// A cell's transmit antenna height, as an offset in metres (the fit's cell index).
    Height(u32),
}

impl Parameter {
    /// True for the antenna's mounting (tilt, bearing, height), fitted as offsets in degrees or
    /// metres; false for the factors on materials and foliage, fitted as their logarithm.
    pub fn is_offset(self) -> bool {
        self.cell().is_some()
    }

    /// The cell whose antenna this parameter moves; `None` for a material or the foliage rate,
    /// which move every link.
    pub fn cell(self) -> Option<usize> {
        match self {
            Parameter::Tilt(c) | Parameter::Azimuth(c) | Parameter::Height(c) => Some(c as usize),
            _ => None,
        }
    }
}

/// How a cell's transmit antenna sits against where the twin mounts it: its tilt and bearing
/// turned by offsets in degrees, raised by an offset in metres.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mount {
    /// Tilt offset, degrees (positive down, as `Antenna::tilt_deg`).
    pub tilt_deg: f64,
    /// Bearing offset, degrees clockwise.
    pub azimuth_deg: f64,
    /// Height offset, metres (positive up).
    pub height_m: f64,
}

/// The material and foliage values a replay evaluates paths with.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// (ε', σ) per material, indexed by discriminant; `None` for foliage and unused materials.
    pub eps_sigma: Vec<Option<(f64, f64)>>,
    /// Slab thickness per material, metres.
    pub thickness: Vec<f64>,
    /// Carrier frequency, Hz.
    pub freq_hz: f64,
    /// Foliage loss (its rate is the parameter; a saturating law keeps its maximum).
    pub foliage: FoliageLoss,
    /// The scattering coefficient S of every surface.
    pub scattering: f64,
}

impl State {
    /// The scene's own materials (its P.2040 values and slab thicknesses), and the foliage loss
    /// and scattering coefficient `opt` traces with.
    pub fn of_scene(scene: &RfScene, freq_hz: f64, opt: &TraceOptions) -> State {
        let n = scene.material_count();
        let (mut eps_sigma, mut thickness) = (vec![None; n], vec![0.0; n]);
        for m in 0..n {
            if let Some((eta, d)) = scene.slab_params(m) {
                eps_sigma[m] = Some(eps_sigma_of(eta, freq_hz));
                thickness[m] = d;
            }
        }
        State {
            eps_sigma,
            thickness,
            freq_hz,
            foliage: opt.foliage_loss(freq_hz),
            scattering: opt.scattering_coefficient,
        }
    }

    /// The value of `p` in this state (ε', σ or dB/m).
    pub fn get(&self, p: Parameter) -> Option<f64> {
        match p {
            Parameter::Permittivity(m) => self.eps_sigma[m as usize].map(|v| v.0),
            Parameter::Conductivity(m) => self.eps_sigma[m as usize].map(|v| v.1),
            Parameter::FoliageDbPerM => Some(self.foliage.db_per_m),
            Parameter::Scattering => Some(self.scattering),
            Parameter::Tilt(_) | Parameter::Azimuth(_) | Parameter::Height(_) => None,
        }
    }

    /// This state with each parameter of `multipliers` multiplied by its factor (ε' kept at 1
    /// or above): how a calibration, fitted as factors on the P.2040 values, applies at any
    /// carrier.
    pub fn scaled(&self, multipliers: &[(Parameter, f64)]) -> State {
        let mut s = self.clone();
        for &(p, k) in multipliers {
            if let Some(v) = s.get(p) {
                let v = v * k;
                s.set(
                    p,
                    if matches!(p, Parameter::Permittivity(_)) {
                        v.max(1.0)
                    } else {
                        v
                    },
                );
            }
        }
        s
    }

    fn set(&mut self, p: Parameter, v: f64) {
        match p {
            Parameter::Permittivity(m) => {
                if let Some(es) = &mut self.eps_sigma[m as usize] {
                    es.0 = v;
                }
            }
            Parameter::Conductivity(m) => {
                if let Some(es) = &mut self.eps_sigma[m as usize] {
                    es.1 = v;
                }
            }
            Parameter::FoliageDbPerM => self.foliage.db_per_m = v,
            Parameter::Scattering => self.scattering = v,
            Parameter::Tilt(_) | Parameter::Azimuth(_) | Parameter::Height(_) => {}
        }
    }

    /// η = ε' − j σ / (ε0 ω) of material `m` (P.2040 eq. (9b), e^{+jωt}).
    fn eta(&self, m: Material) -> Option<C64> {
        let (eps, sigma) = self.eps_sigma[m as usize]?;
        Some(complex_permittivity(eps, sigma, self.freq_hz))
    }

    fn wavelength(&self) -> f64 {
        super::wavelength(self.freq_hz)
    }
}

/// One reflection or transmission of a path, as its replay needs it.
#[derive(Clone, Copy, Debug)]
struct Op {
    transmit: bool,
    /// The leg the wave arrives along (legs run between the transmitter, the reflections and
    /// the receiver: a transmission does not bend the path).
    leg: usize,
    /// Where the path meets the surface as traced: a point of its plane.
    at: DVec3,
    /// The surface's unit normal.
    n: DVec3,
    material: Material,
}

/// A traced path kept as what it does to the field: the transmit antenna's field along its
/// first leg, its reflections and transmissions in order, the receive antenna's pattern along
/// its last, and what does not depend on any parameter (spreading over its length, the
/// roughness factor of its reflections). [`PathReplay::evaluate`] gives its gain `a` in any
/// [`State`] and antenna [`Mount`].
#[derive(Clone, Debug)]
pub struct PathReplay {
    /// The transmit antenna as traced.
    tx: Antenna,
    rx_antenna: Antenna,
    /// The ends as traced.
    from: DVec3,
    to: DVec3,
    /// Each leg's direction as traced.
    legs: Vec<DVec3>,
    ops: Vec<Op>,
    /// The receive antenna's field along the last leg as traced.
    rx: DVec3,
    /// λ / (4π L) over the traced length.
    spreading: f64,
    /// Specular reflections on the path (each keeps √(1 − S²) of the field).
    reflections: i32,
    length_m: f64,
    foliage_m: f64,
}

/// The traced links, each as its replayable paths and the power that stays fixed.
#[derive(Clone, Debug, Default)]
pub struct LinkModel {
    /// The specular paths (reflections and transmissions only).
    pub paths: Vec<PathReplay>,
    /// Power of the paths through an edge, as traced.
    pub fixed_power: f64,
    /// Diffuse power as traced, by how many specular reflections came before the scattering
    /// surface.
    pub diffuse: Vec<f64>,
    /// The scattering coefficient the links were traced with.
    pub traced_scattering: f64,
}

/// What the paths of a trace were evaluated with.
pub struct TraceSetup<'a> {
    /// The scene traced.
    pub scene: &'a RfScene,
    /// Transmit antenna.
    pub tx_antenna: &'a Antenna,
    /// Receive antenna.
    pub rx_antenna: &'a Antenna,
    /// The options traced with.
    pub opt: &'a TraceOptions,
}

impl LinkModel {
    /// The link `tx` -> `rx` traced as `traced`, for replay. The polyline of each specular path
    /// is the transmitter, its interactions and the receiver; the directions, normals and
    /// materials are the scene's, as `path_field::evaluate` took them.
    pub fn new(setup: &TraceSetup, tx: DVec3, rx: DVec3, traced: &LinkPaths) -> LinkModel {
        let mut model = LinkModel {
            paths: Vec::new(),
            fixed_power: 0.0,
            diffuse: traced.diffuse_by_reflections.clone(),
            traced_scattering: setup.opt.scattering_coefficient,
        };
        for p in &traced.paths {
            match PathReplay::new(setup, tx, rx, p) {
                Some(r) => model.paths.push(r),
                None => model.fixed_power += p.a[0] * p.a[0] + p.a[1] * p.a[1],
            }
        }
        model
    }

    /// The link's gain in dB in `state` with its transmit antenna at `mount`, and its
    /// derivative in each of `params`: in the logarithm of a material's or the foliage rate's
    /// value (a factor's derivative at 1), in degrees of an antenna angle, in metres of its
    /// height (the link's own antenna, whatever the cell index says).
    pub fn gain_db(&self, state: &State, params: &[Parameter], mount: Mount) -> (f64, Vec<f64>) {
        let (diffuse, ddiffuse) = self.diffuse_power(state.scattering);
        let mut power = self.fixed_power + diffuse;
        let mut dpower: Vec<f64> = params
            .iter()
            .map(|p| match p {
                Parameter::Scattering => ddiffuse,
                _ => 0.0,
            })
            .collect();
        for p in &self.paths {
            let (a, da) = p.evaluate(state, params, mount);
            power += a.norm_sqr();
            for (acc, d) in dpower.iter_mut().zip(&da) {
                *acc += 2.0 * (a.conj() * d).re;
            }
        }
        if power <= 0.0 {
            return (f64::NEG_INFINITY, vec![0.0; params.len()]);
        }
        let to_db = 10.0 / std::f64::consts::LN_10 / power;
        (
            10.0 * power.log10(),
            dpower.into_iter().map(|d| d * to_db).collect(),
        )
    }

    /// The diffuse power at scattering coefficient `s`, and its derivative in ln s: the traced
    /// power after k specular reflections scales as s² (1 − s²)^k.
    fn diffuse_power(&self, s: f64) -> (f64, f64) {
        let s0 = self.traced_scattering;
        if self.diffuse.is_empty() || s0 <= 0.0 {
            return (0.0, 0.0);
        }
        let (spec, spec0) = ((1.0 - s * s).max(0.0), (1.0 - s0 * s0).max(1e-300));
        let (mut p, mut dp) = (0.0, 0.0);
        for (k, &pk) in self.diffuse.iter().enumerate() {
            let v = if s == s0 {
                pk
            } else {
                pk * (s * s) / (s0 * s0) * (spec / spec0).powi(k as i32)
            };
            p += v;
            // d/d ln s of s² (1 − s²)^k: 2 − 2k s² / (1 − s²).
            dp += v * (2.0 - 2.0 * k as f64 * s * s / spec.max(1e-300));
        }
        (p, dp)
    }
}

/// The step of the central difference a replay's height derivative takes, metres: the image
/// geometry is smooth, so its error (O(step²)) is far below any measurement's.
const HEIGHT_STEP_M: f64 = 0.01;

impl PathReplay {
    /// `path` of the link `tx` -> `rx` as a replay; `None` for a path through an edge.
    pub fn new(setup: &TraceSetup, tx: DVec3, rx: DVec3, path: &Path) -> Option<PathReplay> {
        let scene = setup.scene;
        let mut points = vec![tx];
        let mut ops = Vec::new();
        for i in &path.interactions {
            let transmit = match i.kind {
                InteractionKind::Reflection => false,
                InteractionKind::Transmission => true,
                InteractionKind::Diffraction => return None,
            };
            let at = DVec3::from(i.point);
            ops.push(Op {
                transmit,
                leg: points.len() - 1,
                at,
                n: scene.normals[i.triangle as usize],
                material: scene.material[i.triangle as usize],
            });
            if !transmit {
                points.push(at);
            }
        }
        points.push(rx);
        let reflections = points.len() as i32 - 2;
        let legs: Vec<DVec3> = points
            .windows(2)
            .map(|w| (w[1] - w[0]).normalize())
            .collect();
        let k_last = *legs.last().expect("at least one leg");
        Some(PathReplay {
            tx: *setup.tx_antenna,
            rx_antenna: *setup.rx_antenna,
            from: tx,
            to: rx,
            legs,
            ops,
            rx: DVec3::from(setup.rx_antenna.field((-k_last).to_array())),
            spreading: scene.wavelength / (4.0 * std::f64::consts::PI * path.length_m),
            reflections,
            length_m: path.length_m,
            foliage_m: path.foliage_m,
        })
    }

    /// The path's legs and length with its transmitter raised by `height_m`, by the image
    /// method over its reflecting planes (each the plane of the face it was traced on), the
    /// reflection points moving along them; `None` where a moved point leaves its legs (the
    /// path no longer exists). The faces' edges and what might block a moved leg are not
    /// checked: a move past a tolerance is retraced (the Calibrate stage).
    fn raised(&self, height_m: f64) -> Option<(Vec<DVec3>, f64)> {
        let tx = self.from + DVec3::Z * height_m;
        let planes: Vec<(DVec3, DVec3)> = self
            .ops
            .iter()
            .filter(|o| !o.transmit)
            .map(|o| (o.at, o.n))
            .collect();
        // images[j + 1]: the transmitter mirrored in planes 0..=j.
        let mut images = vec![tx];
        for &(p, n) in &planes {
            let i = images[images.len() - 1];
            images.push(i - 2.0 * (i - p).dot(n) * n);
        }
        let length = (images[planes.len()] - self.to).length();
        let mut points = vec![self.to];
        let mut q = self.to;
        for (k, &(p, n)) in planes.iter().enumerate().rev() {
            let towards = images[k + 1] - q;
            let across = towards.dot(n);
            if across.abs() < 1e-12 {
                return None;
            }
            let t = (p - q).dot(n) / across;
            if !(t > 0.0 && t < 1.0) {
                return None;
            }
            q += towards * t;
            points.push(q);
        }
        points.push(tx);
        points.reverse();
        let legs = points
            .windows(2)
            .map(|w| (w[1] - w[0]).normalize())
            .collect();
        Some((legs, length))
    }

    /// The path's gain `a` in `state` with the transmit antenna at `mount`, and its derivative
    /// in each of `params`: in the logarithm of a material's value or the foliage rate
    /// (analytic: forward through the interactions, each linear in the field and in its two
    /// coefficients, so a derivative is the interaction applied to the field's derivative plus
    /// the coefficients' derivative applied to the field), in degrees of the antenna's tilt and
    /// bearing (the pattern's analytic slopes) and in metres of its height (a central
    /// difference of the image geometry, [`HEIGHT_STEP_M`]).
    pub fn evaluate(&self, state: &State, params: &[Parameter], mount: Mount) -> (C64, Vec<C64>) {
        let zero = C64::new(0.0, 0.0);
        let moved;
        let specular = (1.0 - state.scattering.powi(2)).max(0.0).sqrt();
        let (legs, scale, rx) = if mount.height_m == 0.0 {
            (
                &self.legs[..],
                self.spreading * specular.powi(self.reflections),
                self.rx,
            )
        } else {
            let Some((legs, length)) = self.raised(mount.height_m) else {
                return (zero, vec![zero; params.len()]);
            };
            moved = legs;
            let k_last = moved[moved.len() - 1];
            (
                &moved[..],
                self.spreading * self.length_m / length * specular.powi(self.reflections),
                DVec3::from(self.rx_antenna.field((-k_last).to_array())),
            )
        };
        let lambda = state.wavelength();
        let tx = Antenna {
            tilt_deg: self.tx.tilt_deg + mount.tilt_deg,
            azimuth_deg: self.tx.azimuth_deg + mount.azimuth_deg,
            ..self.tx
        };
        let k0 = legs[0].to_array();
        let mut e = field::real(DVec3::from(tx.field(k0)));
        let mut de = vec![[zero; 3]; params.len()];
        let materials_asked = params
            .iter()
            .any(|p| matches!(p, Parameter::Permittivity(_) | Parameter::Conductivity(_)));
        for op in &self.ops {
            let Some(eta) = state.eta(op.material) else {
                continue;
            };
            let d = legs[op.leg];
            let thickness = state.thickness[op.material as usize];
            let cos = d.dot(op.n).abs().min(1.0);
            let (r, t) = slab(cos, eta, thickness, lambda);
            let (dr, dt) = if materials_asked {
                slab_derivative(cos, eta, thickness, lambda)
            } else {
                ((zero, zero), (zero, zero))
            };
            let (c, dc) = if op.transmit { (t, dt) } else { (r, dr) };
            let apply = |e: &CVec, c: (C64, C64)| -> CVec {
                if op.transmit {
                    field::transmit(e, d, op.n, c)
                } else {
                    field::reflect(e, d, op.n, c).0
                }
            };
            for (j, p) in params.iter().enumerate() {
                let mut next = apply(&de[j], c);
                // dη / d(ln ε') = ε'; dη / d(ln σ) = -j σ / (ε0 ω).
                let deta = match *p {
                    Parameter::Permittivity(m) if m == op.material => C64::new(eta.re, 0.0),
                    Parameter::Conductivity(m) if m == op.material => C64::new(0.0, eta.im),
                    _ => zero,
                };
                if deta.norm_sqr() > 0.0 {
                    let moved = apply(&e, (dc.0 * deta, dc.1 * deta));
                    for (x, y) in next.iter_mut().zip(moved) {
                        *x += y;
                    }
                }
                de[j] = next;
            }
            e = apply(&e, c);
        }
        let scale = scale * state.foliage.amplitude(self.foliage_m);
        let a = field::dot(&e, rx) * scale;
        // d(loss dB)/dγ: the metres in foliage, or m (1 - e^{-γ d / m}) differentiated.
        let dloss = match state.foliage.max_db {
            None => self.foliage_m,
            Some(m) => self.foliage_m * (-state.foliage.db_per_m * self.foliage_m / m).exp(),
        };
        // a ∝ √G of the transmit antenna toward the first leg.
        let (_, slope_tilt, slope_bearing) = if params
            .iter()
            .any(|p| matches!(p, Parameter::Tilt(_) | Parameter::Azimuth(_)))
        {
            tx.gain_slopes_db(k0)
        } else {
            (0.0, 0.0, 0.0)
        };
        let da = params
            .iter()
            .zip(&de)
            .map(|(p, d)| match p {
                Parameter::Tilt(_) => a * (std::f64::consts::LN_10 / 20.0 * slope_tilt),
                Parameter::Azimuth(_) => a * (std::f64::consts::LN_10 / 20.0 * slope_bearing),
                Parameter::Height(_) => {
                    let at = |dh: f64| {
                        let m = Mount {
                            height_m: mount.height_m + dh,
                            ..mount
                        };
                        self.evaluate(state, &[], m).0
                    };
                    (at(HEIGHT_STEP_M) - at(-HEIGHT_STEP_M)) / (2.0 * HEIGHT_STEP_M)
                }
                Parameter::FoliageDbPerM => {
                    a * (-std::f64::consts::LN_10 / 20.0 * dloss * state.foliage.db_per_m)
                }
                // d ln √(1 − S²)^n / d ln S = −n S² / (1 − S²).
                Parameter::Scattering => {
                    let s2 = state.scattering * state.scattering;
                    a * (-(self.reflections as f64) * s2 / (1.0 - s2).max(1e-300))
                }
                _ => field::dot(d, rx) * scale,
            })
            .collect();
        (a, da)
    }
}

/// How a fit holds one parameter: a material's or the foliage rate's as a factor k on its value
/// in each carrier's state (the P.2040 value at that carrier, or the rate), with a Gaussian prior
/// on ln k round `centre` (0: the P.2040 value) of standard deviation `width` and bounds on k;
/// an antenna's tilt, bearing or height as an offset in degrees or metres from where the traced
/// paths put it, the prior round `centre` and the bounds in the same unit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// The parameter.
    pub parameter: Parameter,
    /// The prior's mean of the fitted coordinate (ln k, or the offset). 0 but where the paths
    /// were traced away from the twin's value (an antenna already raised): minus that move.
    pub centre: f64,
    /// The prior's standard deviation of ln k (or of the offset).
    pub width: f64,
    /// Least factor (or offset) allowed.
    pub lo: f64,
    /// Most factor (or offset) allowed.
    pub hi: f64,
}

impl Prior {
    /// The default prior of `p`: ε' within a factor 1.5 at one standard deviation and 3 at the
    /// bounds; σ within a factor 3 and 100; the foliage rate within a factor 2 and 10; the
    /// scattering coefficient within a factor 2 and from 0.1 to 4 times its traced value (a
    /// caller keeps it at most 1: [`Prior::for_scattering`]); a tilt
    /// within 3° and 10° (a mast's tilt is seldom published, and few degrees either way); a
    /// bearing within 5° and 20° (published bearings are surveyed, but to a few degrees); a
    /// height within 3 m and 6 m (heights are seldom published: a mast on a roof of uncertain
    /// height, as the twin's roof + 3 m guesses).
    pub fn default_for(p: Parameter) -> Prior {
        let (width, lo, hi) = match p {
            Parameter::Permittivity(_) => (1.5f64.ln(), 1.0 / 3.0, 3.0),
            Parameter::Conductivity(_) => (3f64.ln(), 0.01, 100.0),
            Parameter::FoliageDbPerM => (2f64.ln(), 0.1, 10.0),
            Parameter::Scattering => (2f64.ln(), 0.1, 4.0),
            Parameter::Tilt(_) => (3.0, -10.0, 10.0),
            Parameter::Azimuth(_) => (5.0, -20.0, 20.0),
            Parameter::Height(_) => (3.0, -6.0, 6.0),
        };
        Prior {
            parameter: p,
            centre: 0.0,
            width,
            lo,
            hi,
        }
    }

    /// The prior of the scattering coefficient traced as `s0` (> 0): [`Prior::default_for`]'s,
    /// the upper bound held where S stays at most 0.95.
    pub fn for_scattering(s0: f64) -> Prior {
        let prior = Prior::default_for(Parameter::Scattering);
        Prior {
            hi: prior.hi.min(0.95 / s0).max(1.0),
            ..prior
        }
    }

    /// The fitted coordinate held within the bounds: ln k, or the offset.
    fn clamp(&self, x: f64) -> f64 {
        if self.parameter.is_offset() {
            x.clamp(self.lo, self.hi)
        } else {
            x.clamp(self.lo.ln(), self.hi.ln())
        }
    }

    /// The fitted coordinate of a value: ln of the factor, or the offset.
    fn coordinate(&self, v: f64) -> f64 {
        if self.parameter.is_offset() {
            v
        } else {
            v.ln()
        }
    }

    /// The value of the fitted coordinate x: the factor e^x, or the offset x.
    fn value(&self, x: f64) -> f64 {
        if self.parameter.is_offset() {
            x
        } else {
            x.exp()
        }
    }
}

/// One measured link for a fit: its traced paths, its cell (the offset it shares), the state
/// of its carrier (an index into the fit's states) and its measured path loss, dB.
#[derive(Clone, Debug)]
pub struct Observation {
    /// The traced link.
    pub model: LinkModel,
    /// The cell (transmitter) index, from 0.
    pub cell: usize,
    /// Which of the fit's states (carriers) the link is evaluated in.
    pub group: usize,
    /// Measured path loss, dB.
    pub loss_db: f64,
}

/// What a fit found.
#[derive(Clone, Debug)]
pub struct Fitted {
    /// Each fitted parameter's factor (an antenna's offset in degrees or metres).
    pub values: Vec<(Parameter, f64)>,
    /// Each parameter's posterior standard deviation in its fitted coordinate (ln k, or the
    /// offset) (the Laplace approximation at the optimum, noise and priors included): near the
    /// prior's width, the links did not constrain it.
    pub spread: Vec<f64>,
    /// Each cell's offset, dB (added to the predicted path loss); 0 for a cell without links.
    pub offsets: Vec<f64>,
    /// Levenberg-Marquardt iterations taken, over every start.
    pub iterations: u32,
    /// The training links' RMSE before and after, dB (each with its own cells' offsets).
    pub rmse_db: (f64, f64),
}

/// What a fit evaluates links in: one state per carrier, and each cell's antenna mount (a cell
/// past the end as traced).
#[derive(Clone, Copy)]
pub struct Setting<'a> {
    /// The states, by the observations' `group`.
    pub states: &'a [State],
    /// The antennas' mounts, by the observations' `cell`.
    pub mounts: &'a [Mount],
}

impl<'a> Setting<'a> {
    /// `states` with every antenna as traced.
    pub fn of(states: &'a [State]) -> Setting<'a> {
        Setting {
            states,
            mounts: &[],
        }
    }

    fn mount(&self, cell: usize) -> Mount {
        self.mounts.get(cell).copied().unwrap_or_default()
    }
}

/// The predicted path loss of `o` in `at` with `offsets`: -gain + the cell's offset; `None`
/// when no path reaches it.
pub fn predicted_loss(o: &Observation, at: Setting, offsets: &[f64]) -> Option<f64> {
    let (g, _) = o.model.gain_db(&at.states[o.group], &[], at.mount(o.cell));
    g.is_finite().then(|| -g + offsets[o.cell])
}

/// Each cell's offset that best fits `obs` in `states` (the mean of measured - predicted): what
/// fitting offsets alone gives.
pub fn fit_offsets(obs: &[Observation], cells: usize, at: Setting) -> Vec<f64> {
    let zero = vec![0.0; cells];
    let (mut sum, mut n) = (vec![0.0; cells], vec![0usize; cells]);
    for o in obs {
        if let Some(p) = predicted_loss(o, at, &zero) {
            sum[o.cell] += o.loss_db - p;
            n[o.cell] += 1;
        }
    }
    sum.iter()
        .zip(&n)
        .map(|(s, &k)| if k > 0 { s / k as f64 } else { 0.0 })
        .collect()
}

/// The RMSE of `obs` in `states` with `offsets`, dB, over the links some path reaches, and how
/// many those are.
pub fn rmse_db<'a>(
    obs: impl IntoIterator<Item = &'a Observation>,
    at: Setting,
    offsets: &[f64],
) -> (f64, usize) {
    let errs: Vec<f64> = obs
        .into_iter()
        .filter_map(|o| predicted_loss(o, at, offsets).map(|p| p - o.loss_db))
        .collect();
    if errs.is_empty() {
        return (f64::NAN, 0);
    }
    let ms = errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64;
    (ms.sqrt(), errs.len())
}

/// Fits a factor on each parameter `priors` name, and one offset per cell, to the links `obs`
/// evaluated in `states` (one per carrier): Levenberg-Marquardt on Σ ((predicted - measured) /
/// noise_db)² plus each prior's (ln k / width)², every step held within the bounds, from
/// several starts ([`PERMITTIVITY_STARTS`]), the lowest cost kept.
/// Deterministic: the same inputs give the same bits at any thread count.
pub fn fit(
    obs: &[Observation],
    cells: usize,
    states: &[State],
    priors: &[Prior],
    noise_db: f64,
) -> Fitted {
    // A slab's coefficients swing with ε' through its thickness resonances, so the cost has a
    // minimum every few tens of per cent of ε': descend from several common factors on every
    // permittivity (the ITU values first) and keep the lowest.
    let permittivity = priors
        .iter()
        .any(|p| matches!(p.parameter, Parameter::Permittivity(_)));
    let starts = PERMITTIVITY_STARTS
        .iter()
        .filter(|&&k| k == 1.0 || permittivity)
        .map(|&k| {
            priors
                .iter()
                .map(|p| match p.parameter {
                    Parameter::Permittivity(_) => p.clamp(k.ln()),
                    _ => 0.0,
                })
                .collect()
        })
        .collect();
    descend_from(obs, cells, states, priors, noise_db, starts)
}

/// As [`fit`], from `from` alone (each parameter's factor or offset; a parameter it does not
/// name starts at the twin's value): a fit carried on after the paths were traced again.
pub fn fit_from(
    obs: &[Observation],
    cells: usize,
    states: &[State],
    priors: &[Prior],
    noise_db: f64,
    from: &[(Parameter, f64)],
) -> Fitted {
    let start = priors
        .iter()
        .map(|p| {
            let v = from.iter().find(|(q, _)| *q == p.parameter);
            p.clamp(v.map_or(0.0, |&(_, v)| p.coordinate(v)))
        })
        .collect();
    descend_from(obs, cells, states, priors, noise_db, vec![start])
}

/// Levenberg-Marquardt from each of `starts` (the parameters' fitted coordinates; each cell's
/// offset starts at its best alone), the lowest cost kept: [`fit`]'s work.
fn descend_from(
    obs: &[Observation],
    cells: usize,
    states: &[State],
    priors: &[Prior],
    noise_db: f64,
    starts: Vec<Vec<f64>>,
) -> Fitted {
    use rayon::prelude::*;
    let params: Vec<Parameter> = priors.iter().map(|p| p.parameter).collect();
    let (np, n) = (priors.len(), priors.len() + cells);
    let values = |x: &[f64]| -> Vec<(Parameter, f64)> {
        priors
            .iter()
            .zip(x)
            .map(|(p, &xi)| (p.parameter, p.value(xi)))
            .collect()
    };
    let states_at = |x: &[f64]| -> Vec<State> {
        let v = values(x);
        states.iter().map(|s| s.scaled(&v)).collect()
    };
    let mounts_at = |x: &[f64]| -> Vec<Mount> { mounts(&values(x), cells) };
    // Residuals and their Jacobian at x (each parameter's fitted coordinate, then the offsets).
    let linearise = |x: &[f64]| -> (Vec<f64>, Vec<Vec<f64>>) {
        let (at, mounted) = (states_at(&x[..np]), mounts_at(&x[..np]));
        let rows: Vec<Option<(f64, Vec<f64>)>> = obs
            .par_iter()
            .map(|o| {
                // A cell's antenna moves only its own links.
                let mine: Vec<usize> = (0..np)
                    .filter(|&j| params[j].cell().is_none_or(|c| c == o.cell))
                    .collect();
                let asked: Vec<Parameter> = mine.iter().map(|&j| params[j]).collect();
                let (g, dg) = o.model.gain_db(&at[o.group], &asked, mounted[o.cell]);
                g.is_finite().then(|| {
                    let mut row = vec![0.0; n];
                    for (&j, d) in mine.iter().zip(&dg) {
                        row[j] = -d / noise_db;
                    }
                    row[np + o.cell] = 1.0 / noise_db;
                    ((-g + x[np + o.cell] - o.loss_db) / noise_db, row)
                })
            })
            .collect();
        let (mut r, mut jac) = (Vec::new(), Vec::new());
        for (ri, row) in rows.into_iter().flatten() {
            r.push(ri);
            jac.push(row);
        }
        for (j, p) in priors.iter().enumerate() {
            r.push((x[j] - p.centre) / p.width);
            let mut row = vec![0.0; n];
            row[j] = 1.0 / p.width;
            jac.push(row);
        }
        (r, jac)
    };
    let cost = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    // Levenberg-Marquardt from x to the nearest minimum: (x, residuals, Jacobian, cost,
    // iterations).
    let descend = |mut x: Vec<f64>| {
        let (mut r, mut jac) = linearise(&x);
        let mut c = cost(&r);
        let mut lambda = 1e-3;
        let mut iterations = 0;
        while iterations < 100 {
            iterations += 1;
            let (a, g) = normal_equations(&r, &jac, n);
            let mut improved = false;
            while lambda < 1e10 {
                let mut damped = a.clone();
                for (i, row) in damped.iter_mut().enumerate() {
                    row[i] += lambda * a[i][i].max(1e-12);
                }
                let Some(step) = solve_spd(damped, g.iter().map(|v| -v).collect()) else {
                    lambda *= 4.0;
                    continue;
                };
                let mut trial: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
                for (t, p) in trial.iter_mut().zip(priors) {
                    *t = p.clamp(*t);
                }
                let (r2, jac2) = linearise(&trial);
                let c2 = cost(&r2);
                if c2 < c {
                    improved = (c - c2) / c.max(1e-300) > 1e-10;
                    (x, r, jac, c) = (trial, r2, jac2, c2);
                    lambda = (lambda / 3.0).max(1e-9);
                    break;
                }
                lambda *= 4.0;
            }
            if !improved {
                break;
            }
        }
        (x, r, jac, c, iterations)
    };
    let offsets0 = fit_offsets(obs, cells, Setting::of(states));
    let before = rmse_db(obs, Setting::of(states), &offsets0).0;
    let mut best: Option<(Vec<f64>, Vec<f64>, Vec<Vec<f64>>, f64, u32)> = None;
    let mut iterations = 0;
    for mut x in starts {
        x.extend(&offsets0);
        let found = descend(x);
        iterations += found.4;
        if best.as_ref().is_none_or(|b| found.3 < b.3) {
            best = Some(found);
        }
    }
    let (x, r, jac, _, _) = best.expect("a fit has a start");
    let fitted = values(&x[..np]);
    let (a, _) = normal_equations(&r, &jac, n);
    let spread = (0..np)
        .map(|j| {
            let unit: Vec<f64> = (0..n).map(|i| if i == j { 1.0 } else { 0.0 }).collect();
            solve_spd(a.clone(), unit).map_or(f64::NAN, |col| col[j].max(0.0).sqrt())
        })
        .collect();
    let offsets = x[np..].to_vec();
    let (at, mounted) = (states_at(&x[..np]), mounts_at(&x[..np]));
    let after = rmse_db(
        obs,
        Setting {
            states: &at,
            mounts: &mounted,
        },
        &offsets,
    )
    .0;
    Fitted {
        values: fitted,
        spread,
        offsets,
        iterations,
        rmse_db: (before, after),
    }
}

/// Each of `cells` cells' antenna mount in `values`.
pub fn mounts(values: &[(Parameter, f64)], cells: usize) -> Vec<Mount> {
    let mut out = vec![Mount::default(); cells];
    for &(p, v) in values {
        match p {
            Parameter::Tilt(c) if (c as usize) < cells => out[c as usize].tilt_deg = v,
            Parameter::Azimuth(c) if (c as usize) < cells => out[c as usize].azimuth_deg = v,
            Parameter::Height(c) if (c as usize) < cells => out[c as usize].height_m = v,
            _ => {}
        }
    }
    out
}

/// The common factors on every permittivity a fit descends from (the ITU values first).
const PERMITTIVITY_STARTS: [f64; 6] = [1.0, 0.7, 0.85, 1.2, 1.45, 1.75];

/// JᵀJ and Jᵀr of residuals `r` with Jacobian rows `jac` over `n` unknowns.
fn normal_equations(r: &[f64], jac: &[Vec<f64>], n: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    let mut a = vec![vec![0.0; n]; n];
    let mut g = vec![0.0; n];
    for (ri, row) in r.iter().zip(jac) {
        for i in 0..n {
            if row[i] == 0.0 {
                continue;
            }
            g[i] += row[i] * ri;
            for k in 0..n {
                a[i][k] += row[i] * row[k];
            }
        }
    }
    (a, g)
}

/// Solves A x = b for a symmetric positive definite A (Cholesky); `None` if A is not.
fn solve_spd(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for j in 0..n {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        if !(d > 0.0) {
            return None;
        }
        let d = d.sqrt();
        a[j][j] = d;
        for i in j + 1..n {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i][k] * b[k];
        }
        b[i] = s / a[i][i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k][i] * b[k];
        }
        b[i] = s / a[i][i];
    }
    Some(b)
}

/// A calibration as a Trace applies it: factors on materials and the foliage rate, and each
/// cell's transmit antenna mount (tilt, bearing and height offsets) by the cell's id.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Calibration {
    /// Factors on the P.2040 values and the foliage rate.
    pub factors: Vec<(Parameter, f64)>,
    /// Antenna mounts by transmitter id.
    pub mounts: std::collections::BTreeMap<String, Mount>,
}

/// The largest antenna height offset a calibration may carry, metres.
pub const MAX_HEIGHT_OFFSET_M: f64 = 100.0;

/// The name under which a calibration keeps `p` (a Calibrate node's output, a Trace's
/// `calibration` input): `calibration/permittivity/<material>`,
/// `calibration/conductivity/<material>`, `calibration/foliage_db_per_m`,
/// `calibration/scattering_coefficient`,
/// `calibration/tilt_deg/<cell id>`, `calibration/azimuth_deg/<cell id>`,
/// `calibration/height_m/<cell id>` (`cell_ids` by the fit's cell index).
pub fn metric_name(p: Parameter, cell_ids: &[String]) -> String {
    let cell = |c: u32| cell_ids.get(c as usize).map_or("?", String::as_str);
    match p {
        Parameter::Permittivity(m) => format!("calibration/permittivity/{}", material_name(m)),
        Parameter::Conductivity(m) => format!("calibration/conductivity/{}", material_name(m)),
        Parameter::FoliageDbPerM => "calibration/foliage_db_per_m".into(),
        Parameter::Scattering => "calibration/scattering_coefficient".into(),
        Parameter::Tilt(c) => format!("calibration/tilt_deg/{}", cell(c)),
        Parameter::Azimuth(c) => format!("calibration/azimuth_deg/{}", cell(c)),
        Parameter::Height(c) => format!("calibration/height_m/{}", cell(c)),
    }
}

fn material_name(m: Material) -> &'static str {
    m.itu_type().unwrap_or("foliage")
}

/// The calibration named in `metrics` ([`metric_name`]); other names are ignored. An error names
/// a factor that is not a positive finite number, an angle that is not finite or past 90°, a
/// height offset that is not finite or past [`MAX_HEIGHT_OFFSET_M`], or a material that does
/// not exist.
pub fn calibration_from(metrics: &crate::artifact::Metrics) -> Result<Calibration, String> {
    let mut out = Calibration::default();
    for (name, &v) in &metrics.values {
        let Some(rest) = name.strip_prefix("calibration/") else {
            continue;
        };
        match rest.split_once('/') {
            Some((kind @ ("permittivity" | "conductivity"), m)) => {
                let material = Material::from_name(m)
                    .filter(|m| *m != Material::Foliage)
                    .ok_or_else(|| format!("{name}: no ITU material is called {m:?}"))?;
                let p = if kind == "permittivity" {
                    Parameter::Permittivity(material)
                } else {
                    Parameter::Conductivity(material)
                };
                out.factors.push((p, positive(name, v)?));
            }
            Some((kind @ ("tilt_deg" | "azimuth_deg"), id)) => {
                if !(v.is_finite() && v.abs() <= 90.0) {
                    return Err(format!(
                        "{name}: expected an offset within ±90 degrees, found {v}"
                    ));
                }
                let mount = out.mounts.entry(id.to_string()).or_default();
                if kind == "tilt_deg" {
                    mount.tilt_deg = v;
                } else {
                    mount.azimuth_deg = v;
                }
            }
            Some(("height_m", id)) => {
                if !(v.is_finite() && v.abs() <= MAX_HEIGHT_OFFSET_M) {
                    return Err(format!(
                        "{name}: expected a height offset within ±{MAX_HEIGHT_OFFSET_M} m, found {v}"
                    ));
                }
                out.mounts.entry(id.to_string()).or_default().height_m = v;
            }
            None if rest == "foliage_db_per_m" => {
                out.factors
                    .push((Parameter::FoliageDbPerM, positive(name, v)?));
            }
            None if rest == "scattering_coefficient" => {
                out.factors
                    .push((Parameter::Scattering, positive(name, v)?));
            }
            _ => {}
        }
    }
    Ok(out)
}

fn positive(name: &str, k: f64) -> Result<f64, String> {
    if k > 0.0 && k.is_finite() {
        Ok(k)
    } else {
        Err(format!(
            "{name}: expected a positive, finite factor, found {k}"
        ))
    }
}

/// `rf` and `opt` with the factors `multipliers` on their materials (P.2040 values at `freq_hz`)
/// and foliage rate; unchanged, to the bit, without factors. Antenna mounts are the caller's.
pub fn apply(
    rf: RfScene,
    opt: &TraceOptions,
    freq_hz: f64,
    multipliers: &[(Parameter, f64)],
) -> (RfScene, TraceOptions) {
    if multipliers.is_empty() {
        return (rf, opt.clone());
    }
    let state = State::of_scene(&rf, freq_hz, opt).scaled(multipliers);
    let mut rf = rf;
    let mut opt = opt.clone();
    for &(p, _) in multipliers {
        match p {
            Parameter::Permittivity(m) | Parameter::Conductivity(m) => {
                if let Some(eta) = state.eta(m) {
                    rf = rf.with_permittivity(m, eta);
                }
            }
            Parameter::FoliageDbPerM => opt.foliage_db_per_m = Some(state.foliage.db_per_m),
            // Sionna's S is a share: at most 1.
            Parameter::Scattering => opt.scattering_coefficient = state.scattering.min(1.0),
            Parameter::Tilt(_) | Parameter::Azimuth(_) | Parameter::Height(_) => {}
        }
    }
    (rf, opt)
}

/// The columns of [`report_rows`].
pub const REPORT_COLUMNS: [&str; 6] = [
    "parameter",
    "twin",
    "calibrated",
    "prior (1 sd)",
    "bounds",
    "posterior sd",
];

/// A Calibrate node's output `m` as a report's table ([`REPORT_COLUMNS`]): each fitted
/// parameter, the twin's value (a material's at the first carrier) and the calibrated one, the
/// prior and bounds it was fitted within, and its posterior spread; factors as ×k, offsets in
/// their unit. Empty when `m` holds no calibration.
pub fn report_rows(m: &crate::artifact::Metrics) -> Vec<[String; 6]> {
    let mut rows = Vec::new();
    for (name, &v) in &m.values {
        let Some(rest) = name.strip_prefix("calibration/") else {
            continue;
        };
        let fit = |what: &str| m.get(&format!("fit/{rest}/{what}"));
        let unit = match rest.split_once('/').map_or(rest, |(kind, _)| kind) {
            "tilt_deg" | "azimuth_deg" => Some("°"),
            "height_m" => Some(" m"),
            _ => None,
        };
        let (w, sd) = (
            fit("prior_width_ln").unwrap_or(f64::NAN),
            fit("spread_ln").unwrap_or(f64::NAN),
        );
        let (lo, hi) = (fit("lo").unwrap_or(f64::NAN), fit("hi").unwrap_or(f64::NAN));
        rows.push(match unit {
            Some(u) => [
                rest.to_string(),
                "as mounted".into(),
                format!("{v:+.2}{u}"),
                format!("±{w:.3}{u}"),
                format!("{lo:+.2}{u} to {hi:+.2}{u}"),
                format!("±{sd:.3}{u}"),
            ],
            None => {
                let itu = fit("itu_at_first_carrier");
                [
                    rest.to_string(),
                    itu.map_or("-".into(), significant),
                    match itu {
                        Some(x) => format!("{} (×{})", significant(x * v), significant(v)),
                        None => format!("×{}", significant(v)),
                    },
                    format!("×/÷{}", significant(w.exp())),
                    format!("×{} to ×{}", significant(lo), significant(hi)),
                    format!("×/÷{}", significant(sd.exp())),
                ]
            }
        });
    }
    rows
}

/// `v` to three significant digits.
fn significant(v: f64) -> String {
    if !(v.is_finite() && v != 0.0) {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    format!("{v:.digits$}")
}

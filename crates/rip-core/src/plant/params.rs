//! The physical parameters of the pendulum and its motor ([`FurutaParams`]) and the one table
//! of their names ([`Param`]): the `[plant]` keys, the Python keywords of
//! `riprs.FurutaParams`, the names in errors and in identification reports are all
//! [`Param::name`].

use serde::{Deserialize, Serialize};

use crate::error::{Result, RipError};

macro_rules! params {
    ($($(#[$doc:meta])* $variant:ident => $name:literal, $field:ident, $zero:literal;)*) => {
        /// A physical parameter of [`FurutaParams`], spelled as in files, Python and errors
        /// ([`name`](Self::name), Quanser's spelling). Every parameter but the gravitational
        /// acceleration [`G`](Self::G) is a `[plant]` key ([`ALL`](Self::ALL)).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        pub enum Param {
            $($(#[$doc])* #[serde(rename = $name)] $variant,)*
        }

        impl Param {
            /// Every parameter, in the declaration order of [`FurutaParams`].
            pub const FIELDS: [Param; Param::COUNT] = [$(Self::$variant,)*];

            /// The name as spelled in files, in Python and in errors.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $name,)*
                }
            }

            /// Whether the parameter may be zero (friction, back-EMF, dead zone); the others
            /// must be positive.
            pub const fn may_be_zero(self) -> bool {
                match self {
                    $(Self::$variant => $zero,)*
                }
            }

            /// The parameter's field of `p`.
            pub fn field(self, p: &mut FurutaParams) -> &mut f64 {
                match self {
                    $(Self::$variant => &mut p.$field,)*
                }
            }
        }
    };
}

params! {
    /// Motor terminal resistance (Ω).
    Rm => "Rm", rm, false;
    /// Motor torque constant (N·m/A).
    Kt => "kt", kt, false;
    /// Motor back-EMF constant (V·s/rad).
    Km => "km", km, true;
    /// Arm mass (kg).
    Mr => "mr", mr, false;
    /// Arm length, motor axis to pendulum joint (m).
    Lr => "Lr", lr, false;
    /// Arm inertia about its centre of mass (kg·m²).
    Jr => "Jr", jr, false;
    /// Pendulum mass (kg).
    Mp => "mp", mp, false;
    /// Pendulum length (m).
    Lp => "Lp", lp, false;
    /// Pendulum inertia about its centre of mass (kg·m²).
    Jp => "Jp", jp, false;
    /// Arm viscous friction (N·m·s/rad).
    Dr => "Dr", dr, true;
    /// Pendulum viscous friction (N·m·s/rad).
    Dp => "Dp", dp, true;
    /// Gravitational acceleration (m/s²): a constant of the place, not of the rig, so not a
    /// `[plant]` key.
    #[serde(skip)]
    G => "g", g, false;
    /// Arm Coulomb friction (N·m).
    Cr => "Cr", cr, true;
    /// Pendulum Coulomb friction (N·m).
    Cp => "Cp", cp, true;
    /// Voltage dead zone of the motor drive (V).
    Vd => "Vd", vd, true;
    /// Stiffness of the cable on the arm (N·m/rad): a torque `−Kc θ` about the arm's zero.
    Kc => "Kc", kc, true;
}

impl Param {
    /// Number of parameters (fields of [`FurutaParams`]).
    pub const COUNT: usize = 16;

    /// The `[plant]` keys (every parameter but [`G`](Self::G)), in the order of the
    /// `[plant]` section and of `riprs.PARAMETERS`; the default perturbed set of
    /// `[monte_carlo]`.
    pub const ALL: [Param; 15] = [
        Self::Mr,
        Self::Lr,
        Self::Jr,
        Self::Mp,
        Self::Lp,
        Self::Jp,
        Self::Dr,
        Self::Dp,
        Self::Rm,
        Self::Kt,
        Self::Km,
        Self::Cr,
        Self::Cp,
        Self::Vd,
        Self::Kc,
    ];

    /// The position in [`FIELDS`](Self::FIELDS) (and in [`FurutaParams::to_array`]).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Parses a `[plant]` key (any of [`ALL`](Self::ALL)).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Parses any field's name, [`G`](Self::G) included (a keyword of `riprs.FurutaParams`).
    pub fn from_field_name(name: &str) -> Option<Self> {
        Self::FIELDS.into_iter().find(|p| p.name() == name)
    }

    /// Why `value` is out of range for this parameter, if it is: finite, and positive or
    /// (for [`may_be_zero`](Self::may_be_zero)) non-negative.
    pub fn check(self, value: f64) -> std::result::Result<(), String> {
        if !value.is_finite() {
            Err(format!("must be finite, got {value}"))
        } else if self.may_be_zero() && value < 0.0 {
            Err(format!("must be non-negative, got {value}"))
        } else if !self.may_be_zero() && value <= 0.0 {
            Err(format!("must be positive, got {value}"))
        } else {
            Ok(())
        }
    }
}

impl std::fmt::Display for Param {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Physical parameters of the pendulum and its motor (SI units).
///
/// Masses, lengths, inertias, `rm`, `kt` and `g` must be positive; `km`, `dr`, `dp`, `cr`,
/// `cp`, `vd`, `kc` may be zero (zero back-EMF and friction give the conservative plant). See the
/// module docs for how each enters the equations of motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FurutaParams {
    /// Motor terminal resistance (Ω).
    pub rm: f64,
    /// Motor torque constant (N·m/A).
    pub kt: f64,
    /// Motor back-EMF constant (V·s/rad).
    pub km: f64,
    /// Arm mass (kg).
    pub mr: f64,
    /// Arm length, motor axis to pendulum joint (m).
    pub lr: f64,
    /// Arm moment of inertia about its own centre of mass (kg·m²).
    pub jr: f64,
    /// Pendulum mass (kg).
    pub mp: f64,
    /// Pendulum length (m); its centre of mass is at `lp/2`.
    pub lp: f64,
    /// Pendulum moment of inertia about its own centre of mass (kg·m²).
    pub jp: f64,
    /// Viscous friction of the arm joint (N·m·s/rad).
    pub dr: f64,
    /// Viscous friction of the pendulum joint (N·m·s/rad).
    pub dp: f64,
    /// Gravitational acceleration (m/s²).
    pub g: f64,
    /// Coulomb friction torque of the arm joint (N·m), smoothed (module docs).
    pub cr: f64,
    /// Coulomb friction torque of the pendulum joint (N·m), smoothed (module docs).
    pub cp: f64,
    /// Voltage dead zone of the motor drive (V): `|u| ≤ vd` does not move the motor.
    pub vd: f64,
    /// Stiffness of the cable on the arm (N·m/rad): the cable torque `−kc θ` about the arm's
    /// zero ([`crate::plant::cable_torque`]).
    pub kc: f64,
}

/// The lumped constants of the equations of motion ([`crate::plant`] module docs), the one
/// place they are computed from the physical parameters ([`FurutaParams::lumped`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lumped {
    /// `J₀ = jr + mr lr²/4 + mp lr²`: the arm-axis inertia at `α = 0` (kg·m²).
    pub j0: f64,
    /// `Jα = jp + mp lp²/4`: the pendulum's inertia about its joint (kg·m²).
    pub ja: f64,
    /// `m₁₂ = mp lr lp/2`: the coupling (kg·m²).
    pub m12: f64,
    /// `G = mp g lp/2`: the gravity stiffness (N·m).
    pub grav: f64,
}

impl Lumped {
    /// `J₀ + Jα`: the arm-axis inertia with the pendulum hanging or upright (kg·m²).
    pub fn arm_axis(&self) -> f64 {
        self.j0 + self.ja
    }

    /// `J₀ − m₁₂²/Jα`, at least `10⁻³ J₀`: the arm's effective inertia when the pendulum's
    /// reaction takes the most of a torque (kg·m²).
    pub fn arm_min(&self) -> f64 {
        (self.j0 - self.m12 * self.m12 / self.ja).max(1e-3 * self.j0)
    }
}

impl FurutaParams {
    /// The lumped constants of the equations of motion ([`Lumped`]).
    pub fn lumped(&self) -> Lumped {
        let p = self;
        Lumped {
            j0: p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr,
            ja: p.jp + p.mp * p.lp * p.lp / 4.0,
            m12: p.mp * p.lr * p.lp / 2.0,
            grav: p.mp * p.g * p.lp / 2.0,
        }
    }

    /// The same rig without its dead zone and Coulomb friction (`V_d = C_r = C_p = 0`): the
    /// smooth model the swing-up plans on while the compensation clears the rest.
    pub fn smooth(&self) -> FurutaParams {
        FurutaParams {
            vd: 0.0,
            cr: 0.0,
            cp: 0.0,
            ..*self
        }
    }

    /// Centroidal inertia of a uniform rod of mass `m` and length `l`, `m l²/12`: the one rule
    /// by which a link whose inertia was not measured is taken from its mass and length (the
    /// presets, the lab file's start set, an identification whose split leaves no positive
    /// inertia).
    pub fn rod_inertia(m: f64, l: f64) -> f64 {
        m * l * l / 12.0
    }

    /// Quanser QUBE-Servo 2 with the rotary-pendulum module.
    ///
    /// Source: Quanser, *QUBE-Servo 2 User Manual* and the parameter script of its
    /// rotary-pendulum workbook (`qube2_rotpen_param.m`): `Rm = 8.4 Ω`,
    /// `kt = km = 0.042`, `Mr = 0.095 kg`, `Lr = 0.085 m`, `Mp = 0.024 kg`, `Lp = 0.129 m`,
    /// `Jr = Mr Lr²/12`, `Jp = Mp Lp²/12`, `g = 9.81`; damping `Dr = 0.001`,
    /// `Dp = 0.00005 N·m·s/rad` (the QUBE-Servo 2 script's values, "tuned heuristically to
    /// match QUBE-Servo 2 response").
    ///
    /// Convention chosen: `Mr Lr²/12` and `Mp Lp²/12` are *centroidal* inertias of uniform rods,
    /// and both links pivot at an end, so the parallel-axis terms `Mr Lr²/4` and `Mp Lp²/4` are
    /// added (arm-axis inertia `Mr Lr²/3`). The workbook's own model uses `Jr` directly as the
    /// inertia about the motor axis (an arm pivoted at its centre, 4× less inertia) and drops the
    /// `Jp sin²α θ̇²` term; both differences are second order for balancing, and ours is the
    /// physically consistent reading of the published masses and lengths. Other sources quote
    /// `Dr = 0.0015`, `Dp = 0.0005` (10× the pendulum damping): that pendulum would have a
    /// damping ratio of 0.18 and lose 1/e of its swing amplitude in half a second, and lose
    /// more energy on one pass from hanging to upright (`4 Dp √(G/Jα) = 1.4 G`) than the whole
    /// swing-up has to supply (`2 G`), unlike the QUBE's freely swinging pendulum; with it no
    /// energy-based swing-up within ±1.5 rad of arm travel reaches upright.
    pub fn qube_servo2() -> Self {
        let (mr, lr, mp, lp) = (0.095, 0.085, 0.024, 0.129);
        Self {
            rm: 8.4,
            kt: 0.042,
            km: 0.042,
            mr,
            lr,
            jr: Self::rod_inertia(mr, lr),
            mp,
            lp,
            jp: Self::rod_inertia(mp, lp),
            dr: 0.001,
            dp: 0.00005,
            g: 9.81,
            cr: 0.0,
            cp: 0.0,
            vd: 0.0,
            kc: 0.0,
        }
    }

    /// Parameters fitted so that the linearisation about upright, discretised by zero-order hold
    /// at `Ts = 0.01 s`, reproduces the paper's `A_d`, `B_d` (eq. (3)).
    ///
    /// The motor constants, both masses and `g` are not identifiable from a linear model (see
    /// [`crate::fit`]) and are fixed at the QUBE-Servo 2 values; `lr`, `lp`, `jr`, `jp`, `dr`,
    /// `dp` come from [`crate::fit::fit_params`] against [`crate::paper::discrete_model`] with
    /// each residual weighted by half the last printed digit of the entry
    /// ([`crate::fit::paper_weights`]). The result reproduces every printed entry of `B_d` and
    /// of `A_d` (except the corrected typo `A_d[0][1]`, see [`crate::paper`]) after rounding;
    /// the largest deviation from the unrounded model is 0.07 of half a printed unit.
    pub fn paper() -> Self {
        Self {
            lr: 1.491_006_775_583e-1,
            lp: 2.788_137_143_023e-1,
            jr: 4.956_499_901_120e-4,
            jp: 3.289_148_708_531e-4,
            dr: 1.894_388_980_126e-3,
            dp: 4.512_959_398_114e-4,
            ..Self::qube_servo2()
        }
    }

    /// The parameters as an array in [`Param::FIELDS`] order (index [`Param::index`]).
    pub fn to_array(&self) -> [f64; Param::COUNT] {
        Param::FIELDS.map(|p| self.get(p))
    }

    /// Builds parameters from an array in [`Param::FIELDS`] order (not validated).
    pub fn from_array(v: [f64; Param::COUNT]) -> Self {
        let mut out = Self::qube_servo2();
        for p in Param::FIELDS {
            out.set(p, v[p.index()]);
        }
        out
    }

    /// The value of `param`.
    pub fn get(&self, param: Param) -> f64 {
        let mut copy = *self;
        *param.field(&mut copy)
    }

    /// Sets `param` to `value` (not validated).
    pub fn set(&mut self, param: Param, value: f64) {
        *param.field(self) = value;
    }

    /// The first parameter out of range and why ([`Param::may_be_zero`] says which may be 0):
    /// the one rule behind [`validate`](Self::validate) and the `[plant]` keys' check.
    pub fn check(&self) -> std::result::Result<(), (Param, String)> {
        Param::FIELDS
            .into_iter()
            .try_for_each(|p| p.check(self.get(p)).map_err(|reason| (p, reason)))
    }

    /// Checks every field; the error names the first bad one by its [`Param::name`].
    pub fn validate(&self) -> Result<()> {
        self.check()
            .map_err(|(p, reason)| RipError::invalid(p.name(), reason))
    }
}

impl Default for FurutaParams {
    fn default() -> Self {
        Self::qube_servo2()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_follows_the_struct() {
        let p = FurutaParams::paper();
        // Each variant reaches its own field: setting one changes exactly that entry.
        for (i, param) in Param::FIELDS.into_iter().enumerate() {
            assert_eq!(param.index(), i);
            let mut q = p;
            q.set(param, 123.0);
            let (a, b) = (p.to_array(), q.to_array());
            for k in 0..Param::COUNT {
                assert_eq!(a[k] != b[k], k == i, "{param}");
            }
            assert_eq!(Param::from_field_name(param.name()), Some(param));
        }
        assert_eq!(FurutaParams::from_array(p.to_array()), p);
        assert_eq!(Param::from_name("g"), None);
        assert_eq!(Param::ALL.len() + 1, Param::COUNT);
    }

    #[test]
    fn the_first_bad_parameter_is_named() {
        let mut p = FurutaParams::paper();
        p.jr = 0.0;
        p.vd = -1.0;
        assert_eq!(p.check().unwrap_err().0, Param::Jr);
        p.jr = 1e-4;
        assert_eq!(p.check().unwrap_err().0, Param::Vd);
        p.vd = 0.0;
        p.km = 0.0;
        assert!(p.validate().is_ok());
    }
}

//! The draft written as a robot description (TOML, commented).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::{ARMATURE, Draft, DraftFoot};

/// A rounded value as the description shows it: at most six decimals, no trailing zeros, no
/// `-0`.
pub(super) fn num(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// `[a, b, c]` with [`num`].
pub(super) fn list3(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

impl Draft {
    /// The description as TOML, commented, with `home` as its `[home]` table.
    pub fn to_toml(&self, home: &BTreeMap<String, f64>) -> String {
        let mut s = String::new();
        self.write_header(&mut s);
        self.write_urdf(&mut s);
        for (side, f) in ["left", "right"].iter().zip(&self.feet) {
            write_foot(&mut s, side, f);
        }
        self.write_hand_and_imu(&mut s);
        self.write_locked_and_armature(&mut s);
        self.write_stance_and_home(&mut s, home);
        s
    }

    /// The comments (the notes), the name, the description, `inertia_floor`.
    pub(super) fn write_header(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "# Drafted by `upc robot init` from the URDF alone (README, \"Bring your robot\").\n\
             # Check it with `upc model --robot <this file>`; every choice below may be edited."
        );
        for n in &self.notes {
            let _ = writeln!(s, "# - {n}");
        }
        let _ = writeln!(s, "name = {:?}", self.name);
        let _ = writeln!(
            s,
            "description = {:?}",
            format!("{} (drafted from {})", self.name, self.path.display())
        );
        if let Some(f) = self.inertia_floor {
            let _ = writeln!(s, "inertia_floor = {f:e}");
        }
    }

    /// `[urdf]`: the file, and the root link's turn.
    pub(super) fn write_urdf(&self, s: &mut String) {
        let _ = writeln!(s, "\n[urdf]");
        if let Some(p) = &self.package {
            let _ = writeln!(s, "package = {p:?}");
        }
        let _ = writeln!(s, "path = {:?}", self.path.display().to_string());
        if let Some(rpy) = self.root_rpy {
            let _ = writeln!(
                s,
                "# The URDF's z axis is not up at its zero posture: its root link turned upright."
            );
            let _ = writeln!(s, "root_rpy = {}", list3(rpy));
        }
    }

    /// `[hand]`, and `[imu]` (or why there is none).
    pub(super) fn write_hand_and_imu(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\n# The right arm's end (where it branches into fingers); its chain from the link \
             both arms share.\n[hand]\nframe = {:?}\nchain_root = {:?}",
            self.hand, self.chain_root
        );
        match &self.imu {
            Some(i) => {
                let _ = writeln!(s, "\n[imu]\nframe = {i:?}");
            }
            None => {
                let _ = writeln!(
                    s,
                    "\n# No frame named *imu*: the IMU is taken on the base, aligned with it."
                );
            }
        }
    }

    /// `[locked]` and `[armature]`, when they list any joint.
    pub(super) fn write_locked_and_armature(&self, s: &mut String) {
        if !self.locked.is_empty() {
            let names: Vec<String> = self.locked.iter().map(|(n, _)| format!("{n:?}")).collect();
            let _ = writeln!(
                s,
                "\n# Fingers and joints that move no mass.\n[locked]\njoints = [{}]",
                names.join(", ")
            );
        }
        if !self.armature.is_empty() {
            let _ = writeln!(
                s,
                "\n# Joints whose link has no mass (a ball joint split into one-axis joints): a \
                 rotor's inertia (kg·m²)\n# keeps the mass matrix invertible where their axes \
                 align.\n[armature]"
            );
            for j in &self.armature {
                let _ = writeln!(s, "{j:?} = {ARMATURE}");
            }
        }
    }

    /// `[stance]`, and `[home]`: `home` with the locked joints at their value.
    pub(super) fn write_stance_and_home(&self, s: &mut String, home: &BTreeMap<String, f64>) {
        let _ = writeln!(
            s,
            "\n# The standing posture, solved at every load from [home] (soles flat, CoM over \
             the feet, base upright\n# and `crouch` lower, the hand at `hand` from the feet's \
             centre on the ground).\n[stance]\ncrouch = {}\nhand = {}",
            num(self.crouch),
            list3(self.hand_target)
        );
        let mut table: BTreeMap<&str, f64> = home.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        for (n, v) in &self.locked {
            if *v != 0.0 {
                table.insert(n, *v);
            }
        }
        let _ = writeln!(
            s,
            "\n# The solved posture (rad), the stance's starting guess; locked joints at their \
             value.\n[home]"
        );
        for (k, v) in table {
            let _ = writeln!(s, "{k} = {:.6}", v);
        }
    }
}

/// `[feet.<side>]`: the link, the sole frame, its contacts.
pub(super) fn write_foot(s: &mut String, side: &str, f: &DraftFoot) {
    let contacts = if f.corner_frames {
        "the URDF's corner frames"
    } else if f.contacts.is_some() {
        "its visual mesh's lowest face's corners"
    } else {
        "its collision geometry's lowest face's corners"
    };
    let _ = writeln!(
        s,
        "\n# The link reaching lowest on this leg; contacts: {contacts}.\n[feet.{side}]"
    );
    let _ = writeln!(s, "frame = {:?}", f.frame);
    let _ = writeln!(s, "link = {:?}", f.link);
    match (f.xyz, f.rpy) {
        (Some(xyz), Some(rpy)) => {
            let _ = writeln!(
                s,
                "origin = {{ xyz = {}, rpy = {} }}",
                list3(xyz),
                list3(rpy)
            );
        }
        (None, Some(rpy)) => {
            let _ = writeln!(s, "origin = {{ rpy = {} }}", list3(rpy));
        }
        _ => {}
    }
    match &f.contacts {
        Some(c) => {
            let list: Vec<String> = c.iter().map(|p| list3(*p)).collect();
            let _ = writeln!(s, "contacts = [{}]", list.join(", "));
        }
        None if f.corner_frames => {
            let _ = writeln!(s, "contacts = \"frames\"");
        }
        None => {
            let _ = writeln!(s, "contacts = \"collision\"");
        }
    }
}

//! The one Ant model both Ant tasks simulate: `assets/ant.xml` as Gymnasium's Ant-v5 has it, and the
//! rllab variant derived from it by swapping the three lines that differ.

use crate::EnvError;

/// The Ant MJCF, as Gymnasium Ant-v5 simulates it.
pub const ANT_V5_MJCF: &str = include_str!("../assets/ant.xml");

/// Which physical constants the Ant gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AntVariant {
    /// Gymnasium Ant-v5: timestep 0.01, gear 150 with ctrlrange ±1, MuJoCo's default contact softness.
    V5,
    /// rllab's Ant (MuJoCo 1.31 era): timestep 0.02, gear 1 with ctrlrange ±150, and softer contacts
    /// (solref .02 1, solimp .8 .8 .01 on every geom).
    Rllab,
}

/// The rllab lines, keyed by the marker that tags the v5 line they replace in `assets/ant.xml`.
const RLLAB_LINES: [(&str, &str); 3] = [
    ("option", r#"<option integrator="RK4" timestep="0.02"/>"#),
    (
        "geom",
        r#"<geom condim="3" conaffinity="0" density="5.0" friction="1 0.5 0.5" margin="0.01" solref=".02 1" solimp=".8 .8 .01" rgba="0.8 0.6 0.4 1"/>"#,
    ),
    ("motor", r#"<motor ctrllimited="true" ctrlrange="-150.0 150.0" gear="1"/>"#),
];

/// The MJCF document for a variant.
pub fn ant_mjcf(variant: AntVariant) -> Result<String, EnvError> {
    match variant {
        AntVariant::V5 => Ok(ANT_V5_MJCF.to_string()),
        AntVariant::Rllab => {
            let mut xml = ANT_V5_MJCF.to_string();
            for (marker, line) in RLLAB_LINES {
                xml = replace_marked_line(&xml, marker, line)?;
            }
            Ok(xml)
        }
    }
}

/// Replaces the element on the one line tagged `<!-- variant: {marker} -->`, keeping its indentation.
fn replace_marked_line(xml: &str, marker: &str, element: &str) -> Result<String, EnvError> {
    let tag = format!("<!-- variant: {marker} -->");
    let tagged = xml.lines().filter(|l| l.trim_end().ends_with(&tag)).count();
    if tagged != 1 {
        return Err(EnvError::Model {
            task: "ant-rllab",
            message: format!("assets/ant.xml must tag exactly one line with {tag:?}, found {tagged}"),
        });
    }
    let mut out = String::with_capacity(xml.len() + element.len());
    for line in xml.lines() {
        if line.trim_end().ends_with(&tag) {
            let indent = &line[..line.len() - line.trim_start().len()];
            out.push_str(indent);
            out.push_str(element);
        } else {
            out.push_str(line);
        }
        out.push('\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Physics;

    #[test]
    fn rllab_variant_changes_only_the_marked_lines() {
        let v5 = ant_mjcf(AntVariant::V5).unwrap();
        let rllab = ant_mjcf(AntVariant::Rllab).unwrap();
        let changed: Vec<_> = v5.lines().zip(rllab.lines()).filter(|(a, b)| a != b).collect();
        assert_eq!(changed.len(), 3);
        assert!(rllab.contains(r#"timestep="0.02""#) && rllab.contains(r#"gear="1""#));
    }

    #[test]
    fn both_variants_compile_with_the_ant_layout() {
        for (variant, timestep) in [(AntVariant::V5, 0.01), (AntVariant::Rllab, 0.02)] {
            let physics = Physics::load("ant", &ant_mjcf(variant).unwrap()).unwrap();
            let m = physics.model().ffi();
            assert_eq!((m.nq, m.nv, m.nu, m.nbody), (15, 14, 8, 14), "{variant:?}");
            assert_eq!(physics.timestep(), timestep);
        }
    }

    #[test]
    fn a_missing_marker_is_an_error() {
        assert!(replace_marked_line("<mujoco/>", "option", "<option/>").is_err());
    }
}

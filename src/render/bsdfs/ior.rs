//! Named indices of refraction that Mitsuba 3.9.1 accepts in scene files.
//!
//! * **Dielectrics** (`int_ior` / `ext_ior` of `dielectric`, `roughdielectric`, `thindielectric`,
//!   `plastic`, `roughplastic`): Mitsuba's `ior_data` table (`include/mitsuba/render/ior.h`,
//!   values "from Hecht, Optics", at about 589 nm). Names are matched case-insensitively, because
//!   Mitsuba lower-cases the name before the lookup. Defaults in Mitsuba: `bk7` inside and `air`
//!   outside for the dielectrics, `polypropylene` inside for the plastics.
//! * **Conductors** (`material` of `conductor` / `roughconductor`): Mitsuba reads the spectral
//!   files `data/ior/<name>.eta.spd` and `<name>.k.spd` and, in its RGB variants, converts each
//!   spectrum once to a linear-sRGB triple (`spectrum_list_to_srgb`, unbounded, with negative
//!   components clamped to 0). The triples below are the ones `scalar_rgb` renders with, read
//!   back from Mitsuba itself for every shipped name by `tests/data/ior/extract_ior.py` (which
//!   also checks them against the plugin's own sample weights). Names are case-sensitive (they
//!   are file names). `none` — Mitsuba's default — is the complex index `0 + 1i`, whose
//!   Fresnel reflectance is exactly 1 at every angle: a perfect mirror times
//!   `specular_reflectance`.

use glam::Vec3;

/// Mitsuba's named dielectric indices of refraction, in Mitsuba's order.
pub const DIELECTRIC_IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.47),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// Mitsuba's conductor presets as `(name, eta, k)`, linear-sRGB triples as `scalar_rgb` uses them;
/// `none` first, then the shipped spectra in byte order of their names.
pub const CONDUCTOR_PRESETS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("none", [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
    (
        "Ag",
        [0.1552762, 0.116727956, 0.13838764],
        [4.8283544, 3.1222224, 2.1469011],
    ),
    (
        "Al",
        [1.6575009, 0.8804047, 0.52124447],
        [9.223811, 6.269502, 4.837004],
    ),
    (
        "AlAs",
        [3.605296, 3.2329378, 2.2163186],
        [0.0006794373, 0.0, 0.007512709],
    ),
    (
        "AlAs_palik",
        [3.605296, 3.2329378, 2.2163186],
        [0.0006794373, 0.0, 0.007512709],
    ),
    (
        "AlSb",
        [0.0, 4.1393747, 4.6692543],
        [0.0, 0.09400908, 1.30057],
    ),
    (
        "AlSb_palik",
        [0.0, 4.1393747, 4.6692543],
        [0.0, 0.09400908, 1.30057],
    ),
    (
        "Au",
        [0.14303598, 0.37530708, 1.4420453],
        [3.982997, 2.3855565, 1.6033592],
    ),
    (
        "Be",
        [4.1850123, 3.1850293, 2.7840612],
        [3.835466, 3.0101223, 2.868994],
    ),
    (
        "Be_palik",
        [4.1850123, 3.1850293, 2.7840612],
        [3.835466, 3.0101223, 2.868994],
    ),
    (
        "Cr",
        [4.3696675, 2.9165053, 1.6549046],
        [5.206547, 4.231306, 3.7546988],
    ),
    ("CsI", [2.1448996, 1.7023189, 1.6624272], [0.0, 0.0, 0.0]),
    (
        "CsI_palik",
        [2.1448996, 1.7023189, 1.6624272],
        [0.0, 0.0, 0.0],
    ),
    (
        "Cu",
        [0.20100547, 0.9237495, 1.1022154],
        [3.9132621, 2.4530451, 2.1420898],
    ),
    (
        "Cu2O",
        [3.5517726, 2.9498696, 2.7518754],
        [0.11420702, 0.19389686, 0.6061339],
    ),
    (
        "Cu2O_palik",
        [3.5517726, 2.9498696, 2.7518754],
        [0.11420702, 0.19389686, 0.6061339],
    ),
    (
        "CuO",
        [3.247541, 2.4478052, 2.2102196],
        [0.52108955, 0.57003075, 0.72217894],
    ),
    (
        "CuO_palik",
        [3.247541, 2.4478052, 2.2102196],
        [0.52108955, 0.57003075, 0.72217894],
    ),
    (
        "Cu_palik",
        [0.21322851, 0.9197154, 1.1024108],
        [3.9218733, 2.4573317, 2.136584],
    ),
    (
        "Hg",
        [2.3989387, 1.440028, 0.9095704],
        [6.327587, 4.371925, 3.4217637],
    ),
    (
        "HgTe",
        [4.77904, 3.2311962, 2.6599011],
        [1.6316127, 1.5808104, 1.7292874],
    ),
    (
        "HgTe_palik",
        [4.77904, 3.2311962, 2.6599011],
        [1.6316127, 1.5808104, 1.7292874],
    ),
    (
        "Hg_palik",
        [2.3989387, 1.440028, 0.9095704],
        [6.327587, 4.371925, 3.4217637],
    ),
    (
        "Ir",
        [3.0863, 2.0821905, 1.6179146],
        [5.592153, 4.067088, 3.267312],
    ),
    (
        "Ir_palik",
        [3.0863, 2.0821905, 1.6179146],
        [5.592153, 4.067088, 3.267312],
    ),
    (
        "K",
        [0.06404319, 0.046409767, 0.038184915],
        [2.1041996, 1.34894, 0.9131259],
    ),
    (
        "K_palik",
        [0.06404319, 0.046409767, 0.038184915],
        [2.1041996, 1.34894, 0.9131259],
    ),
    (
        "Li",
        [0.26579094, 0.19561832, 0.22094862],
        [3.540155, 2.3111234, 1.6686072],
    ),
    (
        "Li_palik",
        [0.26579094, 0.19561832, 0.22094862],
        [3.540155, 2.3111234, 1.6686072],
    ),
    (
        "MgO",
        [2.0895839, 1.6507235, 1.594879],
        [4.3326952e-12, 0.0, 2.4986457e-11],
    ),
    (
        "MgO_palik",
        [2.0895839, 1.6507235, 1.594879],
        [4.3326952e-12, 0.0, 2.4986457e-11],
    ),
    (
        "Mo",
        [4.483974, 3.5251307, 2.7763104],
        [4.1114373, 3.420827, 3.1506073],
    ),
    (
        "Mo_palik",
        [4.483974, 3.5251307, 2.7763104],
        [4.1114373, 3.420827, 3.1506073],
    ),
    (
        "Na_palik",
        [0.060269356, 0.056140948, 0.061988432],
        [3.1792734, 2.1124904, 1.5790411],
    ),
    (
        "Nb",
        [3.420074, 2.7900932, 2.3956294],
        [3.4413946, 2.7376661, 2.5797458],
    ),
    (
        "Nb_palik",
        [3.420074, 2.7900932, 2.3956294],
        [3.4413946, 2.7376661, 2.5797458],
    ),
    (
        "Ni_palik",
        [2.3673046, 1.6633731, 1.4670781],
        [4.4988117, 3.050153, 2.3454392],
    ),
    (
        "Rh",
        [2.5857935, 1.8602164, 1.5542634],
        [6.7822604, 4.702987, 3.976073],
    ),
    (
        "Rh_palik",
        [2.5857935, 1.8602164, 1.5542634],
        [6.7822604, 4.702987, 3.976073],
    ),
    (
        "Se",
        [4.0583115, 2.842935, 2.8208535],
        [0.75404954, 0.6384435, 0.52180755],
    ),
    (
        "Se-e",
        [5.722849, 4.165736, 4.0813384],
        [0.8711363, 1.1051575, 1.5653203],
    ),
    (
        "Se-e_palik",
        [5.722849, 4.165736, 4.0813384],
        [0.8711363, 1.1051575, 1.5653203],
    ),
    (
        "Se_palik",
        [4.0583115, 2.842935, 2.8208535],
        [0.75404954, 0.6384435, 0.52180755],
    ),
    (
        "SiC",
        [3.1723416, 2.5259717, 2.4793706],
        [7.5376636e-07, 0.0, 1.0192531e-05],
    ),
    (
        "SiC_palik",
        [3.1723416, 2.5259717, 2.4793706],
        [7.5376636e-07, 0.0, 1.0192531e-05],
    ),
    ("SnTe", [4.5242496, 1.981645, 1.2815913], [0.0, 0.0, 0.0]),
    (
        "SnTe_palik",
        [4.5242496, 1.981645, 1.2815913],
        [0.0, 0.0, 0.0],
    ),
    (
        "Ta",
        [2.062721, 2.3929389, 2.6279287],
        [2.4083598, 1.7414864, 1.9470278],
    ),
    (
        "Ta_palik",
        [2.062721, 2.3929389, 2.6279287],
        [2.4083598, 1.7414864, 1.9470278],
    ),
    (
        "Te",
        [7.3902335, 4.482105, 2.637106],
        [3.2560222, 3.5270588, 3.2920542],
    ),
    (
        "Te-e",
        [7.508907, 4.2964287, 2.3699877],
        [5.5839286, 4.947205, 3.9975922],
    ),
    (
        "Te-e_palik",
        [7.508907, 4.2964287, 2.3699877],
        [5.5839286, 4.947205, 3.9975922],
    ),
    (
        "Te_palik",
        [7.3902335, 4.482105, 2.637106],
        [3.2560222, 3.5270588, 3.2920542],
    ),
    ("ThF4", [1.8307136, 1.4422286, 1.3876476], [0.0, 0.0, 0.0]),
    (
        "ThF4_palik",
        [1.8307136, 1.4422286, 1.3876476],
        [0.0, 0.0, 0.0],
    ),
    (
        "TiC",
        [3.7005284, 2.8374221, 2.582287],
        [3.265635, 2.3515892, 2.1727905],
    ),
    (
        "TiC_palik",
        [3.7005284, 2.8374221, 2.582287],
        [3.265635, 2.3515892, 2.1727905],
    ),
    (
        "TiN",
        [1.6484497, 1.150516, 1.3798234],
        [3.368328, 1.9434981, 1.1020677],
    ),
    (
        "TiN_palik",
        [1.6484497, 1.150516, 1.3798234],
        [3.368328, 1.9434981, 1.1020677],
    ),
    (
        "TiO2",
        [3.45661, 2.8017359, 2.905175],
        [0.00010526484, 0.0, 0.0006528865],
    ),
    (
        "TiO2-e",
        [3.1065645, 2.5131683, 2.5824444],
        [2.9751605e-05, 0.0, 0.00018269809],
    ),
    (
        "TiO2-e_palik",
        [3.1065645, 2.5131683, 2.5824444],
        [2.9751605e-05, 0.0, 0.00018269809],
    ),
    (
        "TiO2_palik",
        [3.45661, 2.8017359, 2.905175],
        [0.00010526484, 0.0, 0.0006528865],
    ),
    (
        "VC",
        [3.657566, 2.752736, 2.532672],
        [3.0683007, 2.1986873, 1.9631927],
    ),
    (
        "VC_palik",
        [3.657566, 2.752736, 2.532672],
        [3.0683007, 2.1986873, 1.9631927],
    ),
    (
        "VN",
        [2.8656023, 2.119189, 1.9400911],
        [3.0322425, 2.0561156, 1.6163063],
    ),
    (
        "VN_palik",
        [2.8656023, 2.119189, 1.9400911],
        [3.0322425, 2.0561156, 1.6163063],
    ),
    (
        "V_palik",
        [4.277582, 3.5129488, 2.7610714],
        [3.4913008, 2.8894548, 3.111522],
    ),
    (
        "W",
        [4.3708167, 3.3002465, 2.9984074],
        [3.5006406, 2.604874, 2.2732332],
    ),
    (
        "a-C",
        [2.9440458, 2.2271364, 1.9681617],
        [0.8874649, 0.7992985, 0.81529],
    ),
    ("d-C", [2.7087197, 2.3188257, 2.2288976], [0.0, 0.0, 0.0]),
    (
        "d-C_palik",
        [2.7087197, 2.3188257, 2.2288976],
        [0.0, 0.0, 0.0],
    ),
];

/// The index of refraction Mitsuba associates with `name` (case-insensitive), e.g. `"bk7"` →
/// 1.5046, or `None` if Mitsuba would reject the name.
pub fn dielectric_ior(name: &str) -> Option<f32> {
    let lower = name.to_lowercase();
    DIELECTRIC_IORS
        .iter()
        .find(|(n, _)| *n == lower)
        .map(|&(_, ior)| ior)
}

/// The `(eta, k)` RGB triples of Mitsuba's conductor `material` preset `name` (case-sensitive,
/// e.g. `"Au"`, `"Cu_palik"`, `"none"`), or `None` if Mitsuba has no such preset.
pub fn conductor_preset(name: &str) -> Option<(Vec3, Vec3)> {
    CONDUCTOR_PRESETS
        .iter()
        .find(|(n, ..)| *n == name)
        .map(|&(_, eta, k)| (Vec3::from(eta), Vec3::from(k)))
}

/// The accepted dielectric names, comma-separated, for error messages.
pub fn dielectric_names() -> String {
    DIELECTRIC_IORS
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The accepted conductor `material` names, comma-separated, for error messages.
pub fn conductor_names() -> String {
    CONDUCTOR_PRESETS
        .iter()
        .map(|(n, ..)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Rows of a CSV fixture under `tests/data/ior/` (header skipped), split on commas.
    fn fixture(name: &str) -> Vec<Vec<String>> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/ior")
            .join(name);
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        text.lines()
            .skip(1)
            .map(|l| l.split(',').map(str::to_owned).collect())
            .collect()
    }

    /// The dielectric table is exactly Mitsuba's: same names, same order, same f32 values.
    #[test]
    fn dielectrics_match_mitsuba() {
        let rows = fixture("dielectric.csv");
        assert_eq!(rows.len(), DIELECTRIC_IORS.len());
        for (row, &(name, ior)) in rows.iter().zip(DIELECTRIC_IORS) {
            assert_eq!(row[0], name);
            assert_eq!(row[1].parse::<f32>().ok(), Some(ior), "{name}");
            assert_eq!(dielectric_ior(name), Some(ior));
        }
        assert_eq!(dielectric_ior("BK7"), Some(1.5046));
        assert_eq!(dielectric_ior("Water Ice"), Some(1.31));
        assert_eq!(dielectric_ior("glass"), None);
        assert!(dielectric_names().starts_with("vacuum, helium, "));
    }

    /// The conductor table is exactly what Mitsuba's `scalar_rgb` renders with, for every name.
    #[test]
    fn conductors_match_mitsuba() {
        let rows = fixture("conductor.csv");
        assert_eq!(rows.len(), CONDUCTOR_PRESETS.len());
        assert_eq!(rows.len(), 72);
        for (row, &(name, eta, k)) in rows.iter().zip(CONDUCTOR_PRESETS) {
            assert_eq!(row[0], name);
            let vals: Vec<f32> = row[1..]
                .iter()
                .map(|x| x.parse().expect("number"))
                .collect();
            assert_eq!(vals, [eta, k].concat(), "{name}");
            assert_eq!(
                conductor_preset(name),
                Some((Vec3::from(eta), Vec3::from(k)))
            );
        }
        assert_eq!(conductor_preset("none"), Some((Vec3::ZERO, Vec3::ONE)));
        assert_eq!(
            conductor_preset("au"),
            None,
            "file names are case-sensitive"
        );
        let (eta, k) = conductor_preset("Au").expect("gold");
        assert!(
            eta.x < eta.z && k.x > k.z,
            "gold reflects red more than blue"
        );
        assert!(conductor_names().starts_with("none, Ag, Al, "));
    }
}

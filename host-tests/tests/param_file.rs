//! The parameter file as the tools load it (`hils::params_file`, `hils_sil::ParamFile`):
//! the reference file equals the built-in defaults, and bad keys and values are refused
//! with the key named.

#[test]
fn reference_file_loads_and_equals_the_defaults() {
    let path = host_tests::reference_parameters_path();
    let loaded = hils::params_file::load_params(&path)
        .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    assert_eq!(loaded, hils_sil::ParamFile::default());
}

#[test]
fn parameter_files_with_bad_keys_or_values_are_refused_with_the_key_named() {
    let path = host_tests::reference_parameters_path();
    let text = std::fs::read_to_string(&path).unwrap();
    // Misspelt key.
    let bad = text.replace("bogie_mass = 2500.0", "bogie_mas = 2500.0");
    let e = hils::params_file::parse_params(&bad, "variant")
        .unwrap_err()
        .to_string();
    assert!(e.contains("bogie_mas"), "{e}");
    // Value out of range.
    let bad = text.replace("wheelset_mass = 850.0", "wheelset_mass = -850.0");
    let e = hils::params_file::parse_params(&bad, "variant")
        .unwrap_err()
        .to_string();
    assert!(e.contains("vehicle.wheelset_mass"), "{e}");
    // Wrong type.
    let bad = text.replace("model = \"variable\"", "model = \"sometimes\"");
    let e = hils::params_file::parse_params(&bad, "variant")
        .unwrap_err()
        .to_string();
    assert!(e.contains("sometimes") || e.contains("model"), "{e}");
    // A variant with changed values loads and differs only there.
    let variant = text.replace("mu_d0 = 0.38", "mu_d0 = 0.35");
    let p = hils::params_file::parse_params(&variant, "variant").unwrap();
    let mut expected = hils_sil::ParamFile::default();
    expected.plant.friction.mu_d0 = 0.35;
    assert_eq!(p, expected);
}

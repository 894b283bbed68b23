//! Every WGSL module the runtime creates parses and validates with naga, without a GPU.

use grotto_runtime::shaders;

#[test]
fn every_wgsl_module_validates() {
    let all = shaders::all().unwrap();
    let pass_files = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/src/passes"))
        .unwrap()
        .filter(|e| e.as_ref().is_ok_and(|e| e.path().extension().is_some_and(|x| x == "wgsl")))
        .count();
    assert_eq!(all.len(), pass_files, "every passes/*.wgsl must be listed in shaders::all()");
    for (name, src) in all {
        let module = naga::front::wgsl::parse_str(&src)
            .unwrap_or_else(|e| panic!("{name}.wgsl does not parse:\n{}", e.emit_to_string(&src)));
        // f16 packing in f32 shaders: wgpu grants it where the downlevel flag is set, which
        // gpu/device.rs requires of every adapter.
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32,
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}.wgsl does not validate: {e:?}"));
    }
}

#[test]
fn a_broken_shader_is_caught() {
    // The check above must be able to fail: a type error in a composed module is reported.
    let src = shaders::compose("#import scene\nfn f() -> u32 { return params.leaf_size_m; }").unwrap();
    let parsed = naga::front::wgsl::parse_str(&src);
    let invalid = match parsed {
        Err(_) => true,
        Ok(m) => naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&m)
        .is_err(),
    };
    assert!(invalid);
}

#[test]
fn unknown_imports_are_internal_errors() {
    let e = shaders::compose("#import nowhere\n").unwrap_err();
    assert!(matches!(e, grotto_runtime::Error::Internal { .. }), "{e}");
}

#[test]
fn the_storage_buffer_requirement_is_what_the_passes_declare() {
    // gpu/device.rs refuses adapters with fewer storage buffers per stage than the hungriest pass binds.
    let mut most = 0;
    for (name, src) in shaders::all().unwrap() {
        let groups = grotto_runtime::passes::reflect_layouts(&src, wgpu::ShaderStages::COMPUTE).unwrap();
        let storage = groups
            .values()
            .flatten()
            .filter(|e| {
                matches!(e.ty, wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Storage { .. }, .. })
            })
            .count() as u32;
        eprintln!("{name}: {storage} storage buffers");
        most = most.max(storage);
    }
    assert_eq!(most, grotto_runtime::gpu::STORAGE_BUFFERS_NEEDED);
}

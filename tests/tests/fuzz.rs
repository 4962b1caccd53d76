//! Bounded fuzzing of everything that arrives from someone else: wire messages (a
//! scene bundle, an impostor request, a relief texture, a worker's registration) and
//! the files a bundle carries (scene TOML, OBJ, glTF). Random bytes, and valid inputs with
//! random edits, must give an answer — a value or an error naming the problem — never
//! a panic or a hang.
//!
//! The valid inputs edited are the built-in scenes, wire messages made here, and the
//! files of `tests/fuzz-corpus/` (every scene-file key, OBJ statement and glTF feature
//! the loaders read). Each property runs [`CASES`] cases (`RELIEF_FUZZ_CASES=N` for a longer run);
//! failing seeds are kept in `tests/tests/fuzz.proptest-regressions` and replayed first.

use relief_core::relief::SourceProjection;
use std::path::Path;
use std::sync::LazyLock;

use proptest::prelude::*;
use prost::Message;

use relief_core::obj::{count_triangles, load_obj};
use relief_core::reach::Reach;
use relief_core::scene::{SceneLimits, builtin_names, builtin_text, file::parse};
use relief_proto::bundle::{Bundle, bundle_for};
use relief_proto::convert::{
    check_register, check_texture_pb, request_from_pb, texture_from_pb, texture_to_pb,
};
use relief_proto::pb;

/// Cases per property: the issue asked for minutes of fuzzing in CI; this many take
/// about a minute and a half on its 2 cores (65,536 took 11 s), most of it writing and
/// reading OBJ files.
const CASES: u32 = 524_288;

/// Small limits, so that a random scene that happens to be valid builds in no time.
const LIMITS: SceneLimits = SceneLimits {
    max_triangles: 20_000,
    max_objects: 16,
};

/// `valid` with `edits` applied: each `(at, byte)` overwrites, inserts or deletes one
/// byte at `at` (wrapped to the length), by the byte's low bits.
fn edited(valid: &[u8], edits: &[(usize, u8)]) -> Vec<u8> {
    let mut bytes = valid.to_vec();
    for &(at, byte) in edits {
        let at = at % (bytes.len() + 1);
        match byte % 3 {
            0 if at < bytes.len() => bytes[at] = byte,
            1 => bytes.insert(at, byte),
            _ if at < bytes.len() => {
                bytes.remove(at);
            }
            _ => {}
        }
    }
    bytes
}

fn edits() -> impl Strategy<Value = Vec<(usize, u8)>> {
    prop::collection::vec((any::<usize>(), any::<u8>()), 1..16)
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: std::env::var("RELIEF_FUZZ_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(CASES),
        failure_persistence: Some(Box::new(prop::test_runner::FileFailurePersistence::WithSource(
            "proptest-regressions",
        ))),
        ..ProptestConfig::default()
    }
}

/// The scene files edited: the corpus's and the built-in scenes.
static SCENES: LazyLock<Vec<Vec<u8>>> = LazyLock::new(|| {
    let builtins = builtin_names().into_iter().filter_map(builtin_text);
    corpus("toml")
        .into_iter()
        .chain(builtins.map(|text| text.as_bytes().to_vec()))
        .collect()
});

/// The OBJ files edited: the corpus's.
static OBJS: LazyLock<Vec<Vec<u8>>> = LazyLock::new(|| corpus("obj"));

/// The glTF files edited, JSON and binary: the corpus's.
static GLTFS: LazyLock<Vec<(&str, Vec<u8>)>> = LazyLock::new(|| {
    let json = corpus("gltf").into_iter().map(|bytes| ("gltf", bytes));
    json.chain(corpus("glb").into_iter().map(|bytes| ("glb", bytes)))
        .collect()
});

/// The texture the wire's fuzzing edits: 8 × 8, a square of texels whose left rim lists
/// a surface hidden behind the texel one in (the lists' fields are edited too, and
/// checked against the depth plane).
fn seed_texture() -> relief_core::relief::ReliefTexture {
    let eye = glam::Vec3::new(0.0, 0.0, 5.0);
    let bounds = relief_core::bounds::Aabb::from_points([glam::Vec3::splat(-1.0), glam::Vec3::splat(1.0)]);
    let camera =
        relief_core::relief::SourceCamera::facing(eye, &bounds, 8, 8, SourceProjection::Orthographic)
            .expect("camera");
    let mut texture =
        relief_core::relief::ReliefTexture::empty(camera, relief_core::relief::DepthBits::Sixteen, eye);
    for j in 2..6 {
        for i in 2..6 {
            let k = texture.index(i, j);
            texture.depth[k] = 1000;
        }
    }
    texture.hidden = (2..6)
        .map(|j| relief_core::relief::Hidden {
            texel: j * 8 + 2,
            side: 0,
            inward: 1,
            depth: 30_000,
        })
        .collect();
    texture.check_hidden().expect("a well-formed seed");
    texture
}

/// The seed texture's messages, encoded: raw; compressed as a worker would; and, when
/// the worker did not predict its planes, the same marked predicted, so that every
/// decoding path is reached (its depths then garbled, and its list refused unedited).
static TEXTURE_MESSAGES: LazyLock<Vec<Vec<u8>>> = LazyLock::new(|| {
    let raw = texture_to_pb(&seed_texture());
    let compressed = relief_proto::planes::compressed(raw.clone());
    let predicted = pb::ReliefTexture {
        encoding: pb::PlaneEncoding::ZstdDelta.into(),
        ..compressed.clone()
    };
    let mut messages = vec![raw, compressed];
    if messages[1].encoding != predicted.encoding {
        messages.push(predicted);
    }
    messages.iter().map(Message::encode_to_vec).collect()
});

/// Unedited, the seed texture converts with its list whole, sent raw and compressed as
/// a worker would.
#[test]
fn the_seed_texture_converts_with_its_hidden_list() {
    let texture = seed_texture();
    let raw = texture_to_pb(&texture);
    for message in [raw.clone(), relief_proto::planes::compressed(raw)] {
        let back = texture_from_pb("texture", &message).expect("the seed converts");
        assert_eq!(back.hidden, texture.hidden);
    }
}

/// The contents of the corpus files whose names end in `extension`.
fn corpus(extension: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz-corpus");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.expect("corpus entry").path())
        .filter(|path| path.extension().is_some_and(|e| e == extension))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no .{extension} files in {}", dir.display());
    files
        .iter()
        .map(|path| std::fs::read(path).expect("corpus file"))
        .collect()
}

/// Decodes a bundle and, when it decodes, unpacks and loads it within its own
/// directory and small limits.
fn decode_and_load(bytes: Vec<u8>, tag: &str) {
    if let Ok(bundle) = Bundle::decode(bytes) {
        let dir = relief_tests::scratch(tag);
        let _ = bundle.load(&dir, &LIMITS);
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn bundles_decode_or_refuse(bytes in prop::collection::vec(any::<u8>(), 0..2048)) {
        decode_and_load(bytes, "fuzz-bundles");
    }

    #[test]
    fn edited_bundles_decode_or_refuse(edits in edits()) {
        let valid = bundle_for("default").expect("default bundle").encoded;
        decode_and_load(edited(&valid, &edits), "fuzz-edited-bundles");
    }

    #[test]
    fn wire_messages_convert_or_refuse(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        if let Ok(request) = pb::ImpostorRequest::decode(bytes.as_slice()) {
            let _ = request_from_pb(&request);
        }
        if let Ok(texture) = pb::ReliefTexture::decode(bytes.as_slice()) {
            let _ = texture_from_pb("texture", &texture);
        }
        if let Ok(register) = pb::Register::decode(bytes.as_slice()) {
            let _ = check_register(&register);
        }
    }

    #[test]
    fn edited_textures_convert_or_refuse(edits in edits()) {
        for valid in TEXTURE_MESSAGES.iter() {
            if let Ok(texture) = pb::ReliefTexture::decode(edited(valid, &edits).as_slice()) {
                let _ = texture_from_pb("texture", &texture);
                let _ = check_texture_pb("texture", &texture);
            }
        }
    }

    #[test]
    fn scene_files_parse_or_refuse(seed in any::<usize>(), edits in edits(), text in "[ -~\n]{0,200}") {
        let valid = &SCENES[seed % SCENES.len()];
        let edited = String::from_utf8_lossy(&edited(valid, &edits)).into_owned();
        for text in [edited, text] {
            let _ = parse(&text, "fuzz", Path::new("."), Reach::Within(Path::new(".")), &LIMITS);
        }
    }

    #[test]
    fn obj_files_load_or_refuse(seed in any::<usize>(), edits in edits(), bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let valid = &OBJS[seed % OBJS.len()];
        let dir = relief_tests::scratch("fuzz-obj");
        for (k, content) in [edited(valid, &edits), bytes].into_iter().enumerate() {
            let path = dir.join(format!("m{k}.obj"));
            std::fs::write(&path, content).expect("writing the OBJ");
            let _ = count_triangles(&path, Reach::Within(&dir));
            let _ = load_obj(&path, Reach::Within(&dir));
        }
    }
}

proptest! {
    // A quarter of the cases: a glTF case costs about four of the others (its JSON is
    // parsed and validated whole), and the whole run is kept to minutes.
    #![proptest_config(ProptestConfig { cases: config().cases / 4, ..config() })]

    #[test]
    fn gltf_files_load_or_refuse(seed in any::<usize>(), edits in edits(), bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let (extension, valid) = &GLTFS[seed % GLTFS.len()];
        let dir = relief_tests::scratch("fuzz-gltf");
        for (k, content) in [edited(valid, &edits), bytes].into_iter().enumerate() {
            let path = dir.join(format!("m{k}.{extension}"));
            std::fs::write(&path, content).expect("writing the glTF file");
            let _ = relief_core::scene::Scene::load_within(&path.to_string_lossy(), Reach::Within(&dir), &LIMITS);
        }
    }
}

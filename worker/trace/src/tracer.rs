//! Scenes made ready for ray casting: a two-level BVH. One BVH per mesh, shared by
//! the objects that place it (the bottom level, [`ObjectTracer`]), and one over the
//! objects' bounds in the world (the top level, [`Placements`]).

use std::collections::HashMap;
use std::sync::Arc;

use glam::Vec3;
use rayon::prelude::*;

use relief_core::hash::ContentHash;
use relief_core::scene::{Scene, SceneObject};
use relief_core::shading::Lighting;

use crate::bvh::Bvh;
use crate::placements::Placements;

/// One object with its mesh's BVH.
#[derive(Debug, Clone)]
pub struct ObjectTracer {
    pub object: SceneObject,
    /// Shared by the placements of one mesh ([`ObjectTracer::all`]).
    pub bvh: Arc<Bvh>,
}

impl ObjectTracer {
    /// Builds the object's BVH (the tracer keeps a copy of the object).
    pub fn new(object: &SceneObject) -> Self {
        ObjectTracer {
            bvh: Arc::new(Bvh::build(&object.mesh)),
            object: object.clone(),
        }
    }

    /// A tracer for each of `objects`, in order, building each mesh's BVH once (in
    /// parallel): placements of one mesh ([`SceneObject::placed`]), and objects of
    /// meshes alike to the byte, share it.
    pub fn all(objects: Vec<SceneObject>) -> Vec<ObjectTracer> {
        let mut distinct: HashMap<ContentHash, &SceneObject> = HashMap::new();
        for object in &objects {
            distinct.entry(object.hash).or_insert(object);
        }
        let bvhs: HashMap<ContentHash, Arc<Bvh>> = distinct
            .into_par_iter()
            .map(|(hash, object)| (hash, Arc::new(Bvh::build(&object.mesh))))
            .collect();
        objects
            .into_iter()
            .map(|object| ObjectTracer {
                bvh: bvhs[&object.hash].clone(),
                object,
            })
            .collect()
    }
}

/// Every object of a scene with its BVH, the BVH over them, and what shading needs.
#[derive(Debug, Clone)]
pub struct SceneTracer {
    pub objects: Vec<ObjectTracer>,
    /// Over `objects`' world bounds, as [`SceneTracer::new`] found them.
    pub(crate) placements: Placements,
    pub lighting: Lighting,
    pub background: Vec3,
}

impl SceneTracer {
    /// Builds every mesh's BVH, in parallel ([`ObjectTracer::all`]), and the BVH over
    /// the objects.
    pub fn new(scene: &Scene) -> Self {
        let bounds: Vec<_> = scene.objects.iter().map(SceneObject::world_bounds).collect();
        SceneTracer {
            objects: ObjectTracer::all(scene.objects.clone()),
            placements: Placements::build(&bounds),
            lighting: scene.lighting.clone(),
            background: scene.background,
        }
    }
}

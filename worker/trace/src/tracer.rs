//! Scenes made ready for ray casting: one BVH per object.

use glam::Vec3;
use rayon::prelude::*;

use relief_core::scene::{Scene, SceneObject};
use relief_core::shading::Lighting;

use crate::bvh::Bvh;

/// One object with its BVH.
#[derive(Debug, Clone)]
pub struct ObjectTracer {
    pub object: SceneObject,
    pub bvh: Bvh,
}

impl ObjectTracer {
    /// Builds the object's BVH (the tracer keeps a copy of the object).
    pub fn new(object: &SceneObject) -> Self {
        Self::owning(object.clone())
    }

    /// As [`ObjectTracer::new`], taking the object.
    pub fn owning(object: SceneObject) -> Self {
        ObjectTracer {
            bvh: Bvh::build(&object.mesh),
            object,
        }
    }
}

/// Every object of a scene with its BVH, plus what shading needs.
#[derive(Debug, Clone)]
pub struct SceneTracer {
    pub objects: Vec<ObjectTracer>,
    pub lighting: Lighting,
    pub background: Vec3,
}

impl SceneTracer {
    /// Builds every object's BVH, in parallel.
    pub fn new(scene: &Scene) -> Self {
        SceneTracer {
            objects: scene.objects.par_iter().map(ObjectTracer::new).collect(),
            lighting: scene.lighting.clone(),
            background: scene.background,
        }
    }
}

//! Scenes made ready for ray casting: one BVH per object.

use glam::Vec3;
use rayon::prelude::*;

use relief_core::scene::{Scene, SceneObject};
use relief_core::shading::Lighting;

use crate::bvh::{Bvh, Hit, Ray};

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

    /// The closest hit of each ray over all objects, as `(object index, hit)`.
    pub fn closest_hits(&self, rays: &[Ray], hits: &mut [Option<(usize, Hit)>]) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        hits.fill(None);
        let mut batch: Vec<Ray> = Vec::with_capacity(rays.len());
        let mut batch_index: Vec<usize> = Vec::with_capacity(rays.len());
        let mut batch_hits: Vec<Option<Hit>> = Vec::with_capacity(rays.len());
        for (k, o) in self.objects.iter().enumerate() {
            batch.clear();
            batch_index.clear();
            for (r, ray) in rays.iter().enumerate() {
                let t_max = hits[r].map_or(ray.t_max, |(_, h)| h.t);
                let inv = ray.direction.recip();
                if o.object
                    .bounds
                    .ray_interval(ray.origin, inv, ray.t_min, t_max)
                    .is_some()
                {
                    batch.push(Ray { t_max, ..*ray });
                    batch_index.push(r);
                }
            }
            batch_hits.clear();
            batch_hits.resize(batch.len(), None);
            o.bvh.intersect_batch(&batch, &mut batch_hits);
            for (&r, hit) in batch_index.iter().zip(&batch_hits) {
                if let Some(hit) = hit {
                    hits[r] = Some((k, *hit));
                }
            }
        }
    }
}

//! A glTF accessor's elements read from the file's buffers, every offset, stride and
//! length checked. (The `gltf` crate's readers assume what its validation does not
//! check — an index accessor of floats, a view past its buffer — and panic on it; a
//! file here may come from anyone.)

use std::sync::Arc;

use gltf::json::Root;
use gltf::json::accessor::{ComponentType, GenericComponentType, Type};
use gltf::json::validation::Checked;

/// Accessor `index`'s elements, `N` components each, as `f32`: floats as they are,
/// unsigned bytes and shorts (normalized, as texture coordinates may be) over their
/// largest value. `allowed` are the component types accepted.
pub(super) fn floats<const N: usize>(
    root: &Root,
    buffers: &[Arc<[u8]>],
    index: usize,
    allowed: &[ComponentType],
) -> Result<Vec<[f32; N]>, String> {
    let elements = Elements::of(root, buffers, index, N, allowed)?;
    Ok((0..elements.count)
        .map(|e| std::array::from_fn(|k| elements.float(e, k)))
        .collect())
}

/// Accessor `index`'s elements as vertex indices: unsigned byte, short or int scalars.
pub(super) fn indices(root: &Root, buffers: &[Arc<[u8]>], index: usize) -> Result<Vec<u32>, String> {
    let allowed = [ComponentType::U8, ComponentType::U16, ComponentType::U32];
    let elements = Elements::of(root, buffers, index, 1, &allowed)?;
    Ok((0..elements.count).map(|e| elements.unsigned(e, 0)).collect())
}

/// The bytes of an accessor's elements, checked to lie within its view and buffer.
struct Elements<'a> {
    data: &'a [u8],
    stride: usize,
    count: usize,
    component: ComponentType,
}

impl<'a> Elements<'a> {
    fn of(
        root: &Root,
        buffers: &'a [Arc<[u8]>],
        index: usize,
        components: usize,
        allowed: &[ComponentType],
    ) -> Result<Elements<'a>, String> {
        let at = |message: String| format!("accessor {index}: {message}");
        let accessor = root.accessors.get(index).ok_or(format!("no accessor {index}"))?;
        if accessor.sparse.is_some() {
            return Err(at("sparse accessors are not read".into()));
        }
        let dimensions = match accessor.type_ {
            Checked::Valid(Type::Scalar) => 1,
            Checked::Valid(Type::Vec2) => 2,
            Checked::Valid(Type::Vec3) => 3,
            Checked::Valid(Type::Vec4) => 4,
            _ => 0,
        };
        if dimensions != components {
            return Err(at(format!("{components} components an element are needed here")));
        }
        let component = match accessor.component_type {
            Checked::Valid(GenericComponentType(c)) if allowed.contains(&c) => c,
            _ => return Err(at(format!("its components are not of {allowed:?}"))),
        };
        let count = accessor.count.0;
        if count == 0 {
            return Err(at("it has no elements".into()));
        }
        let view = (accessor.buffer_view.as_ref())
            .and_then(|v| root.buffer_views.get(v.value()))
            .ok_or_else(|| at("it has no buffer view".into()))?;
        let buffer = buffers
            .get(view.buffer.value())
            .ok_or_else(|| at(format!("no buffer {}", view.buffer.value())))?;
        let element = (components * component.size()) as u64;
        let stride = view.byte_stride.map_or(element, |s| s.0 as u64);
        if stride < element {
            return Err(at(format!(
                "a stride of {stride} bytes, less than its {element}-byte elements"
            )));
        }
        let view_start = view.byte_offset.map_or(0, |o| o.0);
        let view_end = view_start.checked_add(view.byte_length.0);
        let start = view_start.checked_add(accessor.byte_offset.map_or(0, |o| o.0));
        let end = (count - 1)
            .checked_mul(stride)
            .and_then(|span| span.checked_add(element)?.checked_add(start?));
        let fits = match (start, end, view_end) {
            (Some(_), Some(end), Some(view_end)) => end <= view_end && view_end <= buffer.len() as u64,
            _ => false,
        };
        if !fits {
            return Err(at(format!(
                "{count} elements of {element} bytes every {stride} lie past its buffer view or its buffer's {} bytes",
                buffer.len()
            )));
        }
        let (start, end) = (start.unwrap_or(0) as usize, end.unwrap_or(0) as usize);
        Ok(Elements {
            data: &buffer[start..end],
            stride: stride as usize,
            count: count as usize,
            component,
        })
    }

    /// Component `k` of element `e`, as stored (an unsigned type).
    fn unsigned(&self, e: usize, k: usize) -> u32 {
        let at = e * self.stride + k * self.component.size();
        let bytes = |n: usize| &self.data[at..at + n];
        match self.component {
            ComponentType::U8 | ComponentType::I8 => u32::from(bytes(1)[0]),
            ComponentType::U16 | ComponentType::I16 => {
                u32::from(u16::from_le_bytes([bytes(2)[0], bytes(2)[1]]))
            }
            ComponentType::U32 | ComponentType::F32 => {
                let b = bytes(4);
                u32::from_le_bytes([b[0], b[1], b[2], b[3]])
            }
        }
    }

    /// Component `k` of element `e` as a float (unsigned integers normalized).
    fn float(&self, e: usize, k: usize) -> f32 {
        let raw = self.unsigned(e, k);
        match self.component {
            ComponentType::F32 => f32::from_bits(raw),
            ComponentType::U8 => raw as f32 / f32::from(u8::MAX),
            ComponentType::U16 => raw as f32 / f32::from(u16::MAX),
            ComponentType::I8 | ComponentType::I16 | ComponentType::U32 => raw as f32,
        }
    }
}

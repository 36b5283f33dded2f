//! The application's compute bindings, per command buffer ([`Bound`]): what a conversion
//! ([`crate::vk::own::converter`]) must give back after its dispatch
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#pipelines-bindpoint-commands>,
//! <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#descriptorsets-compatibility>).

use ash::vk;

/// Descriptor set indices a record holds.
pub const SETS: usize = 8;
/// Dynamic offsets a record holds per set.
pub const DYNAMIC: usize = 8;
/// Push-constant bytes a record holds (`maxPushConstantsSize` is at least 128, 256 on desktop
/// drivers).
pub const PUSH_BYTES: usize = 256;
/// Push-constant updates with the compute stage that no later push covers (layout, stages,
/// range) a record holds ([`Bound::push`]).
pub const PUSHES: usize = 8;

#[derive(Clone, Copy, Default)]
pub struct SetBinding {
    pub layout: vk::PipelineLayout,
    pub set: vk::DescriptorSet,
    /// Order of the bind among the command buffer's binds (0: never bound).
    pub seq: u32,
    pub dynamic_count: u32,
    pub dynamic: [u32; DYNAMIC],
}

#[derive(Clone, Copy, Default)]
pub struct PushRange {
    pub layout: vk::PipelineLayout,
    pub stages: vk::ShaderStageFlags,
    pub offset: u32,
    pub size: u32,
    /// Order of the range's latest push among the command buffer's pushes: ranges are given back
    /// in the order the application last pushed them, so the last layout it pushed with (which
    /// decides which earlier push constants stay defined,
    /// <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#descriptorsets-compatibility>)
    /// is the last one again.
    pub seq: u32,
}

/// What the application has bound at the compute bind point of one command buffer, and its
/// push constants (which are not per bind point).
#[derive(Clone, Copy)]
pub struct Bound {
    pub pipeline: vk::Pipeline,
    pub sets: [SetBinding; SETS],
    pub seq: u32,
    pub push: [u8; PUSH_BYTES],
    pub pushes: [PushRange; PUSHES],
    pub push_count: u32,
    /// Something was bound that this record cannot give back.
    pub lost: bool,
    /// Conditional rendering the application made active in this command buffer (buffer, offset,
    /// flags), which the conversion suspends.
    pub conditional: Option<(vk::Buffer, u64, vk::ConditionalRenderingFlagsEXT)>,
    /// A secondary command buffer that inherits conditional rendering: it cannot suspend it.
    pub inherited_conditional: bool,
    /// Maps this recording converted, with the `MAP_EPOCH` of [`crate::vk::convert`] they were
    /// converted at (image 0: none).
    pub converted: [(u64, u64); 4],
    /// Which recording of the command buffer this is (1 for the first): a conversion takes a
    /// slot no conversion of this recording took yet
    /// ([`Slot::used_in`](crate::vk::own::converter::Slot::used_in)).
    pub recording: u64,
    /// The render pass instance whose end writes its density-map offsets: the address of the
    /// shifts its conversion reads (a slot's `shifts_at`) and the texel they are counted in.
    pub open: Option<(usize, [u32; 2])>,
    /// The dynamic render pass instance open in this command buffer was begun suspending: its
    /// ends until the one after the last resumption carry no offsets (the specification ignores
    /// them).
    pub suspended: bool,
    /// Where the next conversion of this recording starts looking for its slot.
    pub next_slot: usize,
}

impl Default for Bound {
    fn default() -> Bound {
        Bound {
            pipeline: vk::Pipeline::null(),
            sets: [SetBinding::default(); SETS],
            seq: 0,
            push: [0; PUSH_BYTES],
            pushes: [PushRange::default(); PUSHES],
            push_count: 0,
            lost: false,
            conditional: None,
            inherited_conditional: false,
            converted: [(0, 0); 4],
            recording: 0,
            open: None,
            suspended: false,
            next_slot: 0,
        }
    }
}

impl Bound {
    pub fn bind_sets(
        &mut self,
        layout: vk::PipelineLayout,
        first: u32,
        sets: &[vk::DescriptorSet],
        dynamic: &[u32],
        dynamic_counts: impl Fn(u32) -> Option<u32>,
    ) {
        self.seq = self.seq.wrapping_add(1).max(1);
        let mut used = 0usize;
        for (i, &set) in sets.iter().enumerate() {
            let index = first as usize + i;
            let n = dynamic_counts(index as u32).unwrap_or(0) as usize;
            let Some(slot) = self.sets.get_mut(index) else {
                self.lost = true;
                return;
            };
            if n > DYNAMIC || used + n > dynamic.len() {
                self.lost = true;
                return;
            }
            slot.layout = layout;
            slot.set = set;
            slot.seq = self.seq;
            slot.dynamic_count = n as u32;
            slot.dynamic[..n].copy_from_slice(&dynamic[used..used + n]);
            used += n;
        }
    }

    /// Notes a `vkCmdPushConstants`. Only what the conversion's own dispatch disturbs is kept: it
    /// pushes constants for the compute stage alone, so a push that names no compute stage leaves
    /// nothing to give back (a graphics pipeline's push constants are untouched by a compute push,
    /// <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#descriptorsets-push-constants>),
    /// and a record that a later push covers (its whole range, for every stage it names) is
    /// dropped: pushing it again would be overwritten by the later one. So an engine's per-draw
    /// graphics pushes and its per-shader compute layouts over one range keep the record at a
    /// range or two, where it used to fill up and give up. The one case the record cannot give
    /// back is a push that overwrites some, not all, of the stages of a recorded range: after it
    /// those stages hold different bytes, and one push cannot restore both (`lost`).
    pub fn push(&mut self, range: PushRange, values: &[u8]) {
        let end = range.offset as u64 + values.len() as u64;
        let n = self.push_count as usize;
        let overlaps = |p: &PushRange| {
            u64::from(p.offset) < end && range.offset < p.offset.saturating_add(p.size)
        };
        if self.pushes[..n].iter().any(|p| {
            overlaps(p) && p.stages.intersects(range.stages) && !range.stages.contains(p.stages)
        }) {
            self.lost = true;
            return;
        }
        if !range.stages.contains(vk::ShaderStageFlags::COMPUTE) {
            return;
        }
        if end > PUSH_BYTES as u64 {
            self.lost = true;
            return;
        }
        let end = end as u32;
        self.push[range.offset as usize..end as usize].copy_from_slice(values);
        self.seq = self.seq.wrapping_add(1).max(1);
        let seq = self.seq;
        let covered = |p: &PushRange| {
            range.stages.contains(p.stages) && range.offset <= p.offset && p.offset + p.size <= end
        };
        let mut kept = 0;
        for i in 0..n {
            if !covered(&self.pushes[i]) {
                self.pushes[kept] = self.pushes[i];
                kept += 1;
            }
        }
        self.push_count = kept as u32;
        match self.pushes.get_mut(kept) {
            Some(slot) => {
                *slot = PushRange { seq, ..range };
                self.push_count += 1;
            }
            None => self.lost = true,
        }
    }
}

/// Binds `bound` again on `cb`: the pipeline, the sets in the order the application bound them,
/// and every push-constant range with its latest bytes.
///
/// # Safety
/// `cb` must be recording on `d`'s device; `bound` the application's state of it.
pub unsafe fn restore(d: &ash::Device, cb: vk::CommandBuffer, bound: &Bound) {
    // SAFETY: the application's own objects, bound as it bound them.
    unsafe {
        if bound.pipeline != vk::Pipeline::null() {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, bound.pipeline);
        }
        let mut order: [usize; SETS] = std::array::from_fn(|i| i);
        order.sort_by_key(|&i| (bound.sets[i].seq, i));
        for i in order {
            let s = &bound.sets[i];
            if s.seq == 0 || s.set == vk::DescriptorSet::null() {
                continue;
            }
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                s.layout,
                i as u32,
                &[s.set],
                &s.dynamic[..s.dynamic_count as usize],
            );
        }
        let mut pushes = bound.pushes;
        let pushes = &mut pushes[..bound.push_count as usize];
        pushes.sort_by_key(|p| p.seq);
        for p in pushes.iter() {
            let at = p.offset as usize;
            d.cmd_push_constants(
                cb,
                p.layout,
                p.stages,
                p.offset,
                &bound.push[at..at + p.size as usize],
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ash::vk::Handle as _;

    #[test]
    fn records_give_back_sets_in_bind_order_and_give_up_past_their_size() {
        let l = vk::PipelineLayout::from_raw(1);
        let mut b = Bound::default();
        b.bind_sets(l, 1, &[vk::DescriptorSet::from_raw(10)], &[4, 8], |_| {
            Some(2)
        });
        b.bind_sets(l, 0, &[vk::DescriptorSet::from_raw(11)], &[], |_| None);
        assert_eq!(b.sets[1].set.as_raw(), 10);
        assert_eq!(
            &b.sets[1].dynamic[..b.sets[1].dynamic_count as usize],
            &[4, 8]
        );
        assert!(b.sets[0].seq > b.sets[1].seq);
        assert!(!b.lost);
        b.bind_sets(
            l,
            SETS as u32,
            &[vk::DescriptorSet::from_raw(12)],
            &[],
            |_| None,
        );
        assert!(b.lost, "a set index past the record");

        let mut b = Bound::default();
        let r = |offset, size| PushRange {
            layout: l,
            stages: vk::ShaderStageFlags::COMPUTE,
            offset,
            size,
            seq: 0,
        };
        b.push(r(0, 4), &[1, 2, 3, 4]);
        b.push(r(0, 4), &[5, 6, 7, 8]);
        assert_eq!(b.push_count, 1, "the same range twice is one range");
        assert_eq!(&b.push[..4], &[5, 6, 7, 8]);
        b.push(r(252, 8), &[0; 8]);
        assert!(b.lost, "bytes past the record");
        let mut b = Bound::default();
        for i in 0..=PUSHES as u32 {
            b.push(r(i * 4, 4), &[0; 4]);
        }
        assert!(b.lost, "more ranges than the record holds");
    }

    /// What an engine records before its eye pass: a pipeline layout per shader and a push per
    /// draw, graphics and compute. Graphics pushes leave nothing to give back, a compute push that
    /// covers an earlier one replaces it, and only a push that overwrites part of a recorded
    /// range's stages gives up.
    #[test]
    fn only_compute_pushes_no_later_push_covers_are_kept() {
        let layout = vk::PipelineLayout::from_raw;
        let r = |l: u64, stages, offset, size| PushRange {
            layout: layout(l),
            stages,
            offset,
            size,
            seq: 0,
        };
        let graphics = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
        let compute = vk::ShaderStageFlags::COMPUTE;
        let mut b = Bound::default();
        for draw in 0..64u64 {
            b.push(r(100 + draw, graphics, 0, 16), &[draw as u8; 16]);
        }
        assert_eq!(
            b.push_count, 0,
            "graphics pushes are not the conversion's to give back"
        );
        assert_eq!(b.push, [0; PUSH_BYTES], "nor are their bytes");
        for shader in 0..20u64 {
            b.push(r(200 + shader, compute, 0, 8), &[shader as u8; 8]);
        }
        assert!(!b.lost);
        assert_eq!(b.push_count, 1, "each compute push covers the one before");
        assert_eq!(
            b.pushes[0].layout,
            layout(219),
            "the last layout pushed with"
        );
        assert_eq!(&b.push[..8], &[19; 8]);
        // A larger range with more stages covers a smaller one; a smaller one does not cover it.
        b.push(r(300, vk::ShaderStageFlags::ALL, 0, 32), &[7; 32]);
        assert_eq!(b.push_count, 1);
        b.push(r(301, vk::ShaderStageFlags::ALL, 8, 4), &[9; 4]);
        assert_eq!(b.push_count, 2);
        assert!(!b.lost);
        // A graphics push over part of the stages of a range the record gives back with all of
        // them: one push can no longer restore both.
        b.push(r(302, graphics, 0, 4), &[1; 4]);
        assert!(b.lost, "stages of one recorded range now differ");
        // Nor can a compute-only push over a range recorded with graphics stages too.
        let mut b = Bound::default();
        b.push(r(1, vk::ShaderStageFlags::VERTEX | compute, 0, 8), &[1; 8]);
        b.push(r(1, graphics, 16, 8), &[2; 8]);
        assert!(!b.lost, "disjoint bytes");
        b.push(r(1, compute, 4, 4), &[3; 4]);
        assert!(b.lost);
    }

    /// Ranges come back in the order of their latest push, not the order first seen: after
    /// pushes with layouts A, B, A (of ranges that do not cover each other) the last layout pushed
    /// with is A again.
    #[test]
    fn push_constants_come_back_in_the_order_last_pushed() {
        let a = vk::PipelineLayout::from_raw(1);
        let b = vk::PipelineLayout::from_raw(2);
        let r = |layout, offset| PushRange {
            layout,
            stages: vk::ShaderStageFlags::COMPUTE,
            offset,
            size: 4,
            seq: 0,
        };
        let mut bound = Bound::default();
        bound.push(r(a, 0), &[1; 4]);
        bound.push(r(b, 4), &[2; 4]);
        bound.push(r(a, 0), &[3; 4]);
        let mut order = bound.pushes[..bound.push_count as usize].to_vec();
        order.sort_by_key(|p| p.seq);
        let layouts: Vec<_> = order.iter().map(|p| p.layout).collect();
        assert_eq!(layouts, [b, a]);
        assert_eq!(&bound.push[..4], &[3; 4]);
    }
}

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
/// Distinct push-constant updates (layout, stages, range) a record holds.
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

    pub fn push(&mut self, range: PushRange, values: &[u8]) {
        let end = range.offset as usize + values.len();
        if end > PUSH_BYTES {
            self.lost = true;
            return;
        }
        self.push[range.offset as usize..end].copy_from_slice(values);
        self.seq = self.seq.wrapping_add(1).max(1);
        let seq = self.seq;
        let known = &mut self.pushes[..self.push_count as usize];
        if let Some(p) = known.iter_mut().find(|p| {
            p.layout == range.layout
                && p.stages == range.stages
                && p.offset == range.offset
                && p.size == range.size
        }) {
            p.seq = seq;
            return;
        }
        match self.pushes.get_mut(self.push_count as usize) {
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

    /// Ranges come back in the order of their latest push, not the order first seen: after
    /// pushes with layouts A, B, A the last layout pushed with is A again.
    #[test]
    fn push_constants_come_back_in_the_order_last_pushed() {
        let a = vk::PipelineLayout::from_raw(1);
        let b = vk::PipelineLayout::from_raw(2);
        let r = |layout| PushRange {
            layout,
            stages: vk::ShaderStageFlags::COMPUTE,
            offset: 0,
            size: 4,
            seq: 0,
        };
        let mut bound = Bound::default();
        bound.push(r(a), &[1; 4]);
        bound.push(r(b), &[2; 4]);
        bound.push(r(a), &[3; 4]);
        let mut order = bound.pushes[..bound.push_count as usize].to_vec();
        order.sort_by_key(|p| p.seq);
        let layouts: Vec<_> = order.iter().map(|p| p.layout).collect();
        assert_eq!(layouts, [b, a]);
        assert_eq!(&bound.push[..4], &[3; 4]);
    }
}

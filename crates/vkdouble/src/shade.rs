//! What a GPU with shading-rate attachments shades: the specification's combiner pipeline, from
//! the pipeline (or dynamic) fragment size through the primitive rate to the attachment's rate, and
//! the clamp to a rate the device lists.
//!
//! Spec: "Fragment Shading Rates", sections "Pipeline Fragment Shading Rate", "Attachment Fragment
//! Shading Rate" and "Combining the Fragment Shading Rates"
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#primsrast-fragment-shading-rate>).

use ash::vk;

/// The fragment size a shading-rate attachment texel encodes: width `2^((v >> 2) & 3)`, height
/// `2^(v & 3)` ("Attachment Fragment Shading Rate").
pub fn decode(code: u8) -> [u32; 2] {
    [1 << ((code >> 2) & 3), 1 << (code & 3)]
}

/// The texel value of a fragment size whose sides are powers of two up to 8.
pub fn encode(size: [u32; 2]) -> u8 {
    let log = |v: u32| (v.max(1).trailing_zeros().min(3)) as u8;
    (log(size[0]) << 2) | log(size[1])
}

/// One combiner step: `a` is the rate so far, `b` the next one.
pub fn combine(op: vk::FragmentShadingRateCombinerOpKHR, a: [u32; 2], b: [u32; 2]) -> [u32; 2] {
    use vk::FragmentShadingRateCombinerOpKHR as Op;
    match op {
        Op::REPLACE => b,
        Op::MIN => [a[0].min(b[0]), a[1].min(b[1])],
        Op::MAX => [a[0].max(b[0]), a[1].max(b[1])],
        // The double reports fragmentShadingRateStrictMultiplyCombiner: an exact product.
        Op::MUL => [a[0] * b[0], a[1] * b[1]],
        _ => a,
    }
}

/// The rate the device uses for a combined `size` it may not support: among the listed rates
/// (`rates`, ordered as vkGetPhysicalDeviceFragmentShadingRatesKHR orders them) one with width and
/// height no larger, of the largest area, then of the smallest aspect ratio; between a wide and a
/// tall one of the same area and ratio the spec leaves the choice to the implementation, and the
/// double takes the first listed (the wider), as the drivers it plays list them.
pub fn clamp(size: [u32; 2], rates: &[[u32; 2]]) -> [u32; 2] {
    let aspect = |r: [u32; 2]| r[0].max(r[1]) / r[0].min(r[1]).max(1);
    let mut best: Option<[u32; 2]> = None;
    for &r in rates {
        if r[0] > size[0] || r[1] > size[1] {
            continue;
        }
        best = match best {
            None => Some(r),
            Some(b) => {
                let (ra, ba) = (r[0] * r[1], b[0] * b[1]);
                if ra > ba || (ra == ba && aspect(r) < aspect(b)) {
                    Some(r)
                } else {
                    Some(b)
                }
            }
        };
    }
    best.unwrap_or([1, 1])
}

/// The pipeline part of a draw's rate: its fragment size and two combiner operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PipelineRate {
    pub size: [u32; 2],
    pub ops: [vk::FragmentShadingRateCombinerOpKHR; 2],
}

impl PipelineRate {
    /// What a pipeline without `VkPipelineFragmentShadingRateStateCreateInfoKHR` has: 1×1 and
    /// `{KEEP, KEEP}`, so the attachment is ignored ("Pipeline Fragment Shading Rate").
    pub const NONE: PipelineRate = PipelineRate {
        size: [1, 1],
        ops: [vk::FragmentShadingRateCombinerOpKHR::KEEP; 2],
    };

    /// The effective fragment size where the attachment texel holds `attachment` (1×1 where the
    /// pass has no attachment). The primitive rate is 1×1: the double does not offer
    /// `primitiveFragmentShadingRate`.
    pub fn effective(self, attachment: [u32; 2], rates: &[[u32; 2]]) -> [u32; 2] {
        let c = combine(self.ops[0], self.size, [1, 1]);
        clamp(combine(self.ops[1], c, attachment), rates)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Profile;
    use vk::FragmentShadingRateCombinerOpKHR as Op;

    fn rates(p: Profile) -> Vec<[u32; 2]> {
        p.fragment_sizes()
    }

    #[test]
    fn codes_round_trip() {
        for w in [1, 2, 4] {
            for h in [1, 2, 4] {
                assert_eq!(decode(encode([w, h])), [w, h]);
            }
        }
        assert_eq!(encode([4, 4]), 10);
        assert_eq!(decode(5), [2, 2]);
    }

    #[test]
    fn without_rate_state_the_attachment_is_ignored() {
        let r = rates(Profile::Nvidia);
        assert_eq!(PipelineRate::NONE.effective([4, 4], &r), [1, 1]);
    }

    #[test]
    fn combiners() {
        let r = rates(Profile::Nvidia);
        let p = |size, ops| PipelineRate { size, ops };
        assert_eq!(
            p([1, 1], [Op::KEEP, Op::REPLACE]).effective([4, 2], &r),
            [4, 2]
        );
        assert_eq!(p([2, 2], [Op::KEEP, Op::MAX]).effective([1, 2], &r), [2, 2]);
        assert_eq!(p([2, 2], [Op::KEEP, Op::MIN]).effective([1, 2], &r), [1, 2]);
        assert_eq!(p([2, 1], [Op::KEEP, Op::MUL]).effective([2, 2], &r), [4, 2]);
        // 4×1 is beyond the aspect ratio: the largest listed rate inside it is 2×1.
        assert_eq!(
            p([4, 1], [Op::KEEP, Op::KEEP]).effective([1, 1], &r),
            [2, 1]
        );
        // Products beyond 4×4 clamp to 4×4.
        assert_eq!(p([4, 4], [Op::KEEP, Op::MUL]).effective([4, 4], &r), [4, 4]);
    }

    #[test]
    fn amd_clamps_to_two_by_two() {
        let r = rates(Profile::Amd);
        let p = PipelineRate {
            size: [1, 1],
            ops: [Op::KEEP, Op::REPLACE],
        };
        assert_eq!(p.effective([4, 4], &r), [2, 2]);
        assert_eq!(p.effective([4, 1], &r), [2, 1]);
        assert_eq!(p.effective([1, 4], &r), [1, 2]);
    }
}

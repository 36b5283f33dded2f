//! The byte size of every struct that may extend `VkDeviceCreateInfo`, by `sType`, so that the
//! layer can copy any of them when it must leave a density-map struct out of a device create info
//! (the preceding structs are relinked on copies; see [`crate::vk::base::chain::ChainCopy`]).
//!
//! The table is every struct whose `structextends` names `VkDeviceCreateInfo` in the Vulkan
//! registry (`xml/vk.xml`) of Vulkan 1.4.359, Vulkan SC's own left out
//! (<https://registry.khronos.org/vulkan/specs/latest/registry.html>): ash 0.38 (the headers of
//! 1.3.281) lacks the newer ones (`VkPhysicalDeviceVulkan14Features`, maintenance 6 to 11, ...), so
//! the sizes are laid out from the registry's member lists by C's rules, once for 64-bit and once
//! for 32-bit pointers. Aliased sTypes (a `KHR` or `EXT` struct promoted to core) share the
//! number, and so the row. A unit test checks every row that ash also defines against ash's own
//! `size_of`.

use ash::vk;

/// `(sType, size with 64-bit pointers, size with 32-bit pointers)`, sorted by sType.
#[rustfmt::skip]
static DEVICE_CREATE_INFO_EXTENDERS: &[(i32, u16, u16)] = &[
    (49, 64, 56), // VkPhysicalDeviceVulkan11Features
    (51, 208, 196), // VkPhysicalDeviceVulkan12Features
    (53, 80, 68), // VkPhysicalDeviceVulkan13Features
    (55, 104, 92), // VkPhysicalDeviceVulkan14Features
    (1000028000, 24, 16), // VkPhysicalDeviceTransformFeedbackFeaturesEXT
    (1000044003, 24, 12), // VkPhysicalDeviceDynamicRenderingFeatures
    (1000050000, 24, 12), // VkPhysicalDeviceCornerSampledImageFeaturesNV
    (1000053001, 32, 20), // VkPhysicalDeviceMultiviewFeatures
    (1000059000, 240, 228), // VkPhysicalDeviceFeatures2
    (1000063000, 24, 12), // VkPhysicalDeviceShaderDrawParametersFeatures
    (1000066000, 24, 12), // VkPhysicalDeviceTextureCompressionASTCHDRFeatures
    (1000067001, 24, 12), // VkPhysicalDeviceASTCDecodeFeaturesEXT
    (1000068001, 24, 12), // VkPhysicalDevicePipelineRobustnessFeatures
    (1000070001, 32, 16), // VkDeviceGroupDeviceCreateInfo
    (1000081001, 24, 16), // VkPhysicalDeviceConditionalRenderingFeaturesEXT
    (1000082000, 24, 16), // VkPhysicalDeviceShaderFloat16Int8Features
    (1000083000, 32, 24), // VkPhysicalDevice16BitStorageFeatures
    (1000102000, 24, 12), // VkPhysicalDeviceDepthClipEnableFeaturesEXT
    (1000108000, 24, 12), // VkPhysicalDeviceImagelessFramebufferFeatures
    (1000110000, 24, 12), // VkPhysicalDeviceRelaxedLineRasterizationFeaturesIMG
    (1000116000, 24, 16), // VkPhysicalDevicePerformanceQueryFeaturesKHR
    (1000120000, 24, 16), // VkPhysicalDeviceVariablePointersFeatures
    (1000133000, 32, 24), // VkPhysicalDeviceGpaFeaturesAMD
    (1000134000, 24, 16), // VkPhysicalDeviceShaderEnqueueFeaturesAMDX
    (1000135009, 24, 16), // VkPhysicalDeviceDescriptorHeapFeaturesEXT
    (1000138000, 24, 16), // VkPhysicalDeviceInlineUniformBlockFeatures
    (1000141000, 32, 20), // VkPhysicalDeviceShaderBfloat16FeaturesKHR
    (1000145001, 24, 12), // VkPhysicalDeviceProtectedMemoryFeatures
    (1000148000, 24, 12), // VkPhysicalDeviceBlendOperationAdvancedFeaturesEXT
    (1000150013, 40, 28), // VkPhysicalDeviceAccelerationStructureFeaturesKHR
    (1000154000, 24, 12), // VkPhysicalDeviceShaderSMBuiltinsFeaturesNV
    (1000156004, 24, 12), // VkPhysicalDeviceSamplerYcbcrConversionFeatures
    (1000161001, 96, 88), // VkPhysicalDeviceDescriptorIndexingFeatures
    (1000163000, 80, 68), // VkPhysicalDevicePortabilitySubsetFeaturesKHR
    (1000164001, 24, 16), // VkPhysicalDeviceShadingRateImageFeaturesNV
    (1000166000, 24, 12), // VkPhysicalDeviceRepresentativeFragmentTestFeaturesNV
    (1000172000, 24, 12), // VkPhysicalDeviceCooperativeMatrixConversionFeaturesQCOM
    (1000173000, 24, 12), // VkPhysicalDeviceElapsedTimerQueryFeaturesQCOM
    (1000175000, 24, 12), // VkPhysicalDeviceShaderSubgroupExtendedTypesFeatures
    (1000177000, 32, 20), // VkPhysicalDevice8BitStorageFeatures
    (1000180000, 24, 16), // VkPhysicalDeviceShaderAtomicInt64Features
    (1000181000, 24, 16), // VkPhysicalDeviceShaderClockFeaturesKHR
    (1000189000, 24, 12), // VkDeviceMemoryOverallocationCreateInfoAMD
    (1000190002, 24, 16), // VkPhysicalDeviceVertexAttributeDivisorFeatures
    (1000201000, 24, 16), // VkPhysicalDeviceComputeShaderDerivativesFeaturesKHR
    (1000202000, 24, 16), // VkPhysicalDeviceMeshShaderFeaturesNV
    (1000203000, 24, 12), // VkPhysicalDeviceFragmentShaderBarycentricFeaturesKHR
    (1000204000, 24, 12), // VkPhysicalDeviceShaderImageFootprintFeaturesNV
    (1000205002, 24, 12), // VkPhysicalDeviceExclusiveScissorFeaturesNV
    (1000207000, 24, 12), // VkPhysicalDeviceTimelineSemaphoreFeatures
    (1000208000, 32, 20), // VkPhysicalDevicePresentTimingFeaturesEXT
    (1000209000, 24, 12), // VkPhysicalDeviceShaderIntegerFunctions2FeaturesINTEL
    (1000211000, 32, 20), // VkPhysicalDeviceVulkanMemoryModelFeatures
    (1000215000, 24, 12), // VkPhysicalDeviceShaderTerminateInvocationFeatures
    (1000218000, 32, 20), // VkPhysicalDeviceFragmentDensityMapFeaturesEXT
    (1000221000, 24, 12), // VkPhysicalDeviceScalarBlockLayoutFeatures
    (1000225002, 24, 16), // VkPhysicalDeviceSubgroupSizeControlFeatures
    (1000226003, 32, 20), // VkPhysicalDeviceFragmentShadingRateFeaturesKHR
    (1000229000, 24, 12), // VkPhysicalDeviceCoherentMemoryFeaturesAMD
    (1000231000, 24, 12), // VkPhysicalDeviceShaderConstantDataFeaturesKHR
    (1000232000, 24, 12), // VkPhysicalDeviceDynamicRenderingLocalReadFeatures
    (1000233000, 24, 12), // VkPhysicalDeviceShaderAbortFeaturesKHR
    (1000234000, 24, 16), // VkPhysicalDeviceShaderImageAtomicInt64FeaturesEXT
    (1000235000, 24, 12), // VkPhysicalDeviceShaderQuadControlFeaturesKHR
    (1000238000, 24, 12), // VkPhysicalDeviceMemoryPriorityFeaturesEXT
    (1000240000, 24, 12), // VkPhysicalDeviceDedicatedAllocationImageAliasingFeaturesNV
    (1000241000, 24, 12), // VkPhysicalDeviceSeparateDepthStencilLayoutsFeatures
    (1000244000, 32, 20), // VkPhysicalDeviceBufferDeviceAddressFeaturesEXT
    (1000248000, 24, 12), // VkPhysicalDevicePresentWaitFeaturesKHR
    (1000249000, 24, 16), // VkPhysicalDeviceCooperativeMatrixFeaturesNV
    (1000250000, 24, 12), // VkPhysicalDeviceCoverageReductionModeFeaturesNV
    (1000251000, 32, 20), // VkPhysicalDeviceFragmentShaderInterlockFeaturesEXT
    (1000252000, 24, 12), // VkPhysicalDeviceYcbcrImageArraysFeaturesEXT
    (1000253000, 24, 12), // VkPhysicalDeviceUniformBufferStandardLayoutFeatures
    (1000254000, 24, 16), // VkPhysicalDeviceProvokingVertexFeaturesEXT
    (1000257000, 32, 20), // VkPhysicalDeviceBufferDeviceAddressFeatures
    (1000259000, 40, 32), // VkPhysicalDeviceLineRasterizationFeatures
    (1000260000, 64, 56), // VkPhysicalDeviceShaderAtomicFloatFeaturesEXT
    (1000261000, 24, 12), // VkPhysicalDeviceHostQueryResetFeatures
    (1000265000, 24, 12), // VkPhysicalDeviceIndexTypeUint8Features
    (1000267000, 24, 12), // VkPhysicalDeviceExtendedDynamicStateFeaturesEXT
    (1000269000, 24, 12), // VkPhysicalDevicePipelineExecutablePropertiesFeaturesKHR
    (1000270000, 24, 12), // VkPhysicalDeviceHostImageCopyFeatures
    (1000272000, 32, 20), // VkPhysicalDeviceMapMemoryPlacedFeaturesEXT
    (1000273000, 64, 56), // VkPhysicalDeviceShaderAtomicFloat2FeaturesEXT
    (1000275000, 24, 12), // VkPhysicalDeviceSwapchainMaintenance1FeaturesKHR
    (1000276000, 24, 12), // VkPhysicalDeviceShaderDemoteToHelperInvocationFeatures
    (1000277007, 24, 12), // VkPhysicalDeviceDeviceGeneratedCommandsFeaturesNV
    (1000278000, 24, 12), // VkPhysicalDeviceInheritedViewportScissorFeaturesNV
    (1000280000, 24, 12), // VkPhysicalDeviceShaderIntegerDotProductFeatures
    (1000281000, 24, 12), // VkPhysicalDeviceTexelBufferAlignmentFeaturesEXT
    (1000283000, 32, 24), // VkPhysicalDeviceDepthBiasControlFeaturesEXT
    (1000284000, 24, 12), // VkPhysicalDeviceDeviceMemoryReportFeaturesEXT
    (1000284001, 40, 20), // VkDeviceDeviceMemoryReportCreateInfoEXT
    (1000286000, 32, 20), // VkPhysicalDeviceRobustness2FeaturesKHR
    (1000287002, 24, 16), // VkPhysicalDeviceCustomBorderColorFeaturesEXT
    (1000288000, 24, 12), // VkPhysicalDeviceTextureCompressionASTC3DFeaturesEXT
    (1000292000, 24, 12), // VkPhysicalDevicePresentBarrierFeaturesNV
    (1000294001, 24, 12), // VkPhysicalDevicePresentIdFeaturesKHR
    (1000295000, 24, 12), // VkPhysicalDevicePrivateDataFeatures
    (1000295001, 24, 12), // VkDevicePrivateDataCreateInfo
    (1000297000, 24, 12), // VkPhysicalDevicePipelineCreationCacheControlFeatures
    (1000300000, 24, 12), // VkPhysicalDeviceDiagnosticsConfigFeaturesNV
    (1000300001, 24, 12), // VkDeviceDiagnosticsConfigCreateInfoNV
    (1000302001, 24, 12), // VkPhysicalDeviceQueuePerfHintFeaturesQCOM
    (1000303000, 32, 20), // VkPhysicalDeviceImageProcessing3FeaturesQCOM
    (1000304000, 24, 12), // VkPhysicalDeviceShaderMultipleWaitQueuesFeaturesQCOM
    (1000305000, 24, 12), // VkPhysicalDeviceShaderSplitBarrierFeaturesEXT
    (1000307003, 24, 12), // VkPhysicalDeviceCudaKernelLaunchFeaturesNV
    (1000309000, 72, 64), // VkPhysicalDeviceTileShadingFeaturesQCOM
    (1000314007, 24, 12), // VkPhysicalDeviceSynchronization2Features
    (1000316002, 32, 24), // VkPhysicalDeviceDescriptorBufferFeaturesEXT
    (1000318006, 24, 12), // VkPhysicalDeviceDeviceAddressCommandsFeaturesKHR
    (1000320000, 24, 12), // VkPhysicalDeviceGraphicsPipelineLibraryFeaturesEXT
    (1000321000, 24, 12), // VkPhysicalDeviceShaderEarlyAndLateFragmentTestsFeaturesAMD
    (1000323000, 24, 12), // VkPhysicalDeviceShaderSubgroupUniformControlFlowFeaturesKHR
    (1000325000, 24, 12), // VkPhysicalDeviceZeroInitializeWorkgroupMemoryFeatures
    (1000326001, 32, 20), // VkPhysicalDeviceFragmentShadingRateEnumsFeaturesNV
    (1000327001, 24, 16), // VkPhysicalDeviceRayTracingMotionBlurFeaturesNV
    (1000328000, 40, 28), // VkPhysicalDeviceMeshShaderFeaturesEXT
    (1000330000, 24, 12), // VkPhysicalDeviceYcbcr2Plane444FormatsFeaturesEXT
    (1000332000, 24, 12), // VkPhysicalDeviceFragmentDensityMap2FeaturesEXT
    (1000335000, 24, 12), // VkPhysicalDeviceImageRobustnessFeatures
    (1000336000, 32, 24), // VkPhysicalDeviceWorkgroupMemoryExplicitLayoutFeaturesKHR
    (1000338000, 24, 12), // VkPhysicalDeviceImageCompressionControlFeaturesEXT
    (1000339000, 24, 12), // VkPhysicalDeviceAttachmentFeedbackLoopLayoutFeaturesEXT
    (1000340000, 24, 16), // VkPhysicalDevice4444FormatsFeaturesEXT
    (1000341000, 24, 16), // VkPhysicalDeviceFaultFeaturesEXT
    (1000342000, 32, 20), // VkPhysicalDeviceRasterizationOrderAttachmentAccessFeaturesEXT
    (1000344000, 24, 12), // VkPhysicalDeviceRGBA10X6FormatsFeaturesEXT
    (1000347000, 40, 28), // VkPhysicalDeviceRayTracingPipelineFeaturesKHR
    (1000348013, 24, 12), // VkPhysicalDeviceRayQueryFeaturesKHR
    (1000351000, 24, 12), // VkPhysicalDeviceMutableDescriptorTypeFeaturesEXT
    (1000352000, 24, 12), // VkPhysicalDeviceVertexInputDynamicStateFeaturesEXT
    (1000354000, 24, 12), // VkPhysicalDeviceAddressBindingReportFeaturesEXT
    (1000355000, 24, 12), // VkPhysicalDeviceDepthClipControlFeaturesEXT
    (1000356000, 24, 16), // VkPhysicalDevicePrimitiveTopologyListRestartFeaturesEXT
    (1000361000, 24, 12), // VkPhysicalDevicePresentModeFifoLatestReadyFeaturesKHR
    (1000369001, 24, 12), // VkPhysicalDeviceSubpassShadingFeaturesHUAWEI
    (1000370000, 24, 12), // VkPhysicalDeviceInvocationMaskFeaturesHUAWEI
    (1000371001, 24, 12), // VkPhysicalDeviceExternalMemoryRDMAFeaturesNV
    (1000372001, 24, 12), // VkPhysicalDevicePipelinePropertiesFeaturesEXT
    (1000375000, 24, 12), // VkPhysicalDeviceFrameBoundaryFeaturesEXT
    (1000376000, 24, 12), // VkPhysicalDeviceMultisampledRenderToSingleSampledFeaturesEXT
    (1000377000, 32, 20), // VkPhysicalDeviceExtendedDynamicState2FeaturesEXT
    (1000381000, 24, 12), // VkPhysicalDeviceColorWriteEnableFeaturesEXT
    (1000382000, 32, 20), // VkPhysicalDevicePrimitivesGeneratedQueryFeaturesEXT
    (1000386000, 24, 16), // VkPhysicalDeviceRayTracingMaintenance1FeaturesKHR
    (1000387000, 24, 12), // VkPhysicalDeviceShaderUntypedPointersFeaturesKHR
    (1000388000, 24, 12), // VkPhysicalDeviceGlobalPriorityQueryFeatures
    (1000390000, 24, 12), // VkPhysicalDeviceVideoEncodeRgbConversionFeaturesVALVE
    (1000391000, 24, 12), // VkPhysicalDeviceImageViewMinLodFeaturesEXT
    (1000392000, 24, 12), // VkPhysicalDeviceMultiDrawFeaturesEXT
    (1000393000, 24, 16), // VkPhysicalDeviceImage2DViewOf3DFeaturesEXT
    (1000395000, 32, 20), // VkPhysicalDeviceShaderTileImageFeaturesEXT
    (1000396005, 32, 20), // VkPhysicalDeviceOpacityMicromapFeaturesEXT
    (1000397000, 24, 12), // VkPhysicalDeviceDisplacementMicromapFeaturesNV
    (1000404000, 24, 16), // VkPhysicalDeviceClusterCullingShaderFeaturesHUAWEI
    (1000411000, 24, 16), // VkPhysicalDeviceBorderColorSwizzleFeaturesEXT
    (1000412000, 24, 12), // VkPhysicalDevicePageableDeviceLocalMemoryFeaturesEXT
    (1000413000, 24, 12), // VkPhysicalDeviceMaintenance4Features
    (1000416000, 24, 16), // VkPhysicalDeviceShaderSubgroupRotateFeatures
    (1000417000, 24, 12), // VkDeviceQueueShaderCoreControlCreateInfoARM
    (1000417001, 24, 12), // VkPhysicalDeviceSchedulingControlsFeaturesARM
    (1000418000, 24, 12), // VkPhysicalDeviceImageSlicedViewOf3DFeaturesEXT
    (1000420000, 24, 12), // VkPhysicalDeviceDescriptorSetHostMappingFeaturesVALVE
    (1000421000, 24, 12), // VkPhysicalDeviceDepthClampZeroOneFeaturesKHR
    (1000422000, 24, 12), // VkPhysicalDeviceNonSeamlessCubeMapFeaturesEXT
    (1000424000, 24, 12), // VkPhysicalDeviceRenderPassStripedFeaturesARM
    (1000425000, 24, 12), // VkPhysicalDeviceFragmentDensityMapOffsetFeaturesEXT
    (1000426000, 24, 12), // VkPhysicalDeviceCopyMemoryIndirectFeaturesNV
    (1000427000, 24, 12), // VkPhysicalDeviceMemoryDecompressionFeaturesEXT
    (1000428000, 32, 20), // VkPhysicalDeviceDeviceGeneratedCommandsComputeFeaturesNV
    (1000429008, 24, 16), // VkPhysicalDeviceRayTracingLinearSweptSpheresFeaturesNV
    (1000430000, 24, 12), // VkPhysicalDeviceLinearColorAttachmentFeaturesNV
    (1000434000, 24, 12), // VkPhysicalDeviceShaderMaximalReconvergenceFeaturesKHR
    (1000437000, 24, 12), // VkPhysicalDeviceImageCompressionControlSwapchainFeaturesEXT
    (1000440000, 32, 20), // VkPhysicalDeviceImageProcessingFeaturesQCOM
    (1000451000, 32, 20), // VkPhysicalDeviceNestedCommandBufferFeaturesEXT
    (1000455000, 144, 132), // VkPhysicalDeviceExtendedDynamicState3FeaturesEXT
    (1000458000, 24, 12), // VkPhysicalDeviceSubpassMergeFeedbackFeaturesEXT
    (1000460009, 40, 32), // VkPhysicalDeviceTensorFeaturesARM
    (1000460018, 24, 12), // VkPhysicalDeviceDescriptorBufferTensorFeaturesARM
    (1000462000, 24, 12), // VkPhysicalDeviceShaderModuleIdentifierFeaturesEXT
    (1000464000, 24, 12), // VkPhysicalDeviceOpticalFlowFeaturesNV
    (1000465000, 24, 12), // VkPhysicalDeviceLegacyDitheringFeaturesEXT
    (1000466000, 24, 12), // VkPhysicalDevicePipelineProtectedAccessFeatures
    (1000468000, 24, 12), // VkPhysicalDeviceExternalFormatResolveFeaturesANDROID
    (1000470000, 24, 12), // VkPhysicalDeviceMaintenance5Features
    (1000476000, 24, 12), // VkPhysicalDeviceAntiLagFeaturesAMD
    (1000478000, 24, 12), // VkPhysicalDeviceDenseGeometryFormatFeaturesAMDX
    (1000479002, 24, 12), // VkPhysicalDevicePresentId2FeaturesKHR
    (1000480001, 24, 12), // VkPhysicalDevicePresentWait2FeaturesKHR
    (1000481000, 24, 12), // VkPhysicalDeviceRayTracingPositionFetchFeaturesKHR
    (1000482000, 24, 12), // VkPhysicalDeviceShaderObjectFeaturesEXT
    (1000483000, 24, 12), // VkPhysicalDevicePipelineBinaryFeaturesKHR
    (1000483008, 24, 12), // VkDevicePipelineBinaryInternalCacheControlKHR
    (1000484000, 24, 12), // VkPhysicalDeviceTilePropertiesFeaturesQCOM
    (1000485000, 24, 12), // VkPhysicalDeviceAmigoProfilingFeaturesSEC
    (1000488000, 24, 12), // VkPhysicalDeviceMultiviewPerViewViewportsFeaturesQCOM
    (1000490000, 24, 12), // VkPhysicalDeviceRayTracingInvocationReorderFeaturesNV
    (1000491000, 24, 16), // VkPhysicalDeviceCooperativeVectorFeaturesNV
    (1000492000, 24, 12), // VkPhysicalDeviceExtendedSparseAddressSpaceFeaturesNV
    (1000495000, 24, 12), // VkPhysicalDeviceLegacyVertexAttributesFeaturesEXT
    (1000497000, 24, 12), // VkPhysicalDeviceShaderCoreBuiltinsFeaturesARM
    (1000498000, 24, 12), // VkPhysicalDevicePipelineLibraryGroupHandlesFeaturesEXT
    (1000499000, 24, 12), // VkPhysicalDeviceDynamicRenderingUnusedAttachmentsFeaturesEXT
    (1000504000, 24, 12), // VkPhysicalDeviceInternallySynchronizedQueuesFeaturesKHR
    (1000506000, 24, 16), // VkPhysicalDeviceCooperativeMatrixFeaturesKHR
    (1000507006, 40, 28), // VkPhysicalDeviceDataGraphFeaturesARM
    (1000510000, 24, 12), // VkPhysicalDeviceMultiviewPerViewRenderAreasFeaturesQCOM
    (1000513004, 24, 12), // VkPhysicalDeviceVideoEncodeAV1FeaturesKHR
    (1000514000, 24, 12), // VkPhysicalDeviceVideoDecodeVP9FeaturesKHR
    (1000515000, 24, 12), // VkPhysicalDeviceVideoMaintenance1FeaturesKHR
    (1000516000, 24, 16), // VkPhysicalDevicePerStageDescriptorSetFeaturesNV
    (1000518000, 24, 12), // VkPhysicalDeviceImageProcessing2FeaturesQCOM
    (1000519001, 24, 12), // VkPhysicalDeviceCubicWeightsFeaturesQCOM
    (1000520000, 24, 12), // VkPhysicalDeviceYcbcrDegammaFeaturesQCOM
    (1000521000, 24, 12), // VkPhysicalDeviceCubicClampFeaturesQCOM
    (1000524000, 24, 12), // VkPhysicalDeviceAttachmentFeedbackLoopDynamicStateFeaturesEXT
    (1000527000, 24, 16), // VkPhysicalDeviceUnifiedImageLayoutsFeaturesKHR
    (1000528000, 24, 12), // VkPhysicalDeviceShaderFloatControls2Features
    (1000529004, 24, 12), // VkPhysicalDeviceExternalMemoryScreenBufferFeaturesQNX
    (1000544000, 24, 12), // VkPhysicalDeviceShaderExpectAssumeFeatures
    (1000545000, 24, 12), // VkPhysicalDeviceMaintenance6Features
    (1000546000, 24, 12), // VkPhysicalDeviceDescriptorPoolOverallocationFeaturesNV
    (1000547000, 24, 12), // VkPhysicalDeviceTileMemoryHeapFeaturesQCOM
    (1000549000, 24, 16), // VkPhysicalDeviceCopyMemoryIndirectFeaturesKHR
    (1000552004, 24, 12), // VkPhysicalDeviceVideoEncodeIntraRefreshFeaturesKHR
    (1000553009, 24, 12), // VkPhysicalDeviceVideoEncodeQuantizationMapFeaturesKHR
    (1000555000, 24, 12), // VkPhysicalDeviceRawAccessChainsFeaturesNV
    (1000556000, 24, 12), // VkExternalComputeQueueDeviceCreateInfoNV
    (1000558000, 24, 12), // VkPhysicalDeviceShaderRelaxedExtendedInstructionFeaturesKHR
    (1000559000, 24, 12), // VkPhysicalDeviceCommandBufferInheritanceFeaturesNV
    (1000562000, 24, 12), // VkPhysicalDeviceMaintenance7FeaturesKHR
    (1000563000, 24, 12), // VkPhysicalDeviceShaderAtomicFloat16VectorFeaturesNV
    (1000564000, 24, 12), // VkPhysicalDeviceShaderReplicatedCompositesFeaturesEXT
    (1000567000, 24, 16), // VkPhysicalDeviceShaderFloat8FeaturesEXT
    (1000568000, 24, 12), // VkPhysicalDeviceRayTracingValidationFeaturesNV
    (1000569000, 24, 12), // VkPhysicalDeviceClusterAccelerationStructureFeaturesNV
    (1000570000, 24, 12), // VkPhysicalDevicePartitionedAccelerationStructureFeaturesNV
    (1000572000, 24, 16), // VkPhysicalDeviceDeviceGeneratedCommandsFeaturesEXT
    (1000573000, 32, 24), // VkPhysicalDeviceFaultFeaturesKHR
    (1000574000, 24, 12), // VkPhysicalDeviceMaintenance8FeaturesKHR
    (1000575000, 24, 12), // VkPhysicalDeviceImageAlignmentControlFeaturesMESA
    (1000579000, 32, 20), // VkPhysicalDeviceShaderFmaFeaturesKHR
    (1000580001, 24, 12), // VkPhysicalDevicePushConstantBankFeaturesNV
    (1000581000, 24, 12), // VkPhysicalDeviceRayTracingInvocationReorderFeaturesEXT
    (1000582000, 24, 12), // VkPhysicalDeviceDepthClampControlFeaturesEXT
    (1000584000, 24, 12), // VkPhysicalDeviceMaintenance9FeaturesKHR
    (1000586000, 24, 12), // VkPhysicalDeviceVideoMaintenance2FeaturesKHR
    (1000590000, 24, 12), // VkPhysicalDeviceHdrVividFeaturesHUAWEI
    (1000593000, 48, 36), // VkPhysicalDeviceCooperativeMatrix2FeaturesNV
    (1000596000, 24, 12), // VkPhysicalDevicePipelineOpacityMicromapFeaturesARM
    (1000598000, 24, 12), // VkPhysicalDeviceVideoEncodeFeedback2FeaturesKHR
    (1000605000, 24, 12), // VkPhysicalDevicePerformanceCountersByRegionFeaturesARM
    (1000607000, 24, 12), // VkPhysicalDeviceShaderInstrumentationFeaturesARM
    (1000608000, 24, 12), // VkPhysicalDeviceVertexAttributeRobustnessFeaturesEXT
    (1000609000, 24, 12), // VkPhysicalDeviceFormatPackFeaturesARM
    (1000611000, 24, 12), // VkPhysicalDeviceFragmentDensityMapLayeredFeaturesVALVE
    (1000613001, 24, 12), // VkPhysicalDevicePresentMeteringFeaturesNV
    (1000616000, 24, 12), // VkPhysicalDeviceMultisampledRenderToSwapchainFeaturesEXT
    (1000620000, 24, 12), // VkPhysicalDeviceZeroInitializeDeviceMemoryFeaturesEXT
    (1000623000, 24, 12), // VkPhysicalDeviceOpacityMicromapFeaturesKHR
    (1000627000, 24, 12), // VkPhysicalDeviceShader64BitIndexingFeaturesEXT
    (1000628000, 24, 12), // VkPhysicalDeviceCustomResolveFeaturesEXT
    (1000629000, 24, 12), // VkPhysicalDeviceDataGraphModelFeaturesQCOM
    (1000630000, 24, 12), // VkPhysicalDeviceMaintenance10FeaturesKHR
    (1000631000, 24, 12), // VkPhysicalDeviceDataGraphOpticalFlowFeaturesARM
    (1000635000, 24, 12), // VkPhysicalDeviceShaderLongVectorFeaturesEXT
    (1000637000, 24, 12), // VkPhysicalDevicePipelineCacheIncrementalModeFeaturesSEC
    (1000642000, 24, 12), // VkPhysicalDeviceShaderUniformBufferUnsizedArrayFeaturesEXT
    (1000645001, 24, 12), // VkPhysicalDeviceComputeOccupancyPriorityFeaturesNV
    (1000657000, 24, 12), // VkPhysicalDeviceMaintenance11FeaturesKHR
    (1000659000, 40, 28), // VkPhysicalDeviceCooperativeMatrixMaintenance1FeaturesEXT
    (1000662000, 24, 12), // VkPhysicalDeviceShaderSubgroupPartitionedFeaturesEXT
    (1000668004, 24, 12), // VkPhysicalDeviceExtendedFlagsFeaturesKHR
    (1000672000, 32, 24), // VkPhysicalDeviceShaderOCPMicroscalingTypesFeaturesEXT
    (1000673000, 32, 24), // VkPhysicalDeviceShaderMixedFloatDotProductFeaturesVALVE
    (1000674000, 24, 12), // VkPhysicalDeviceThrottleHintFeaturesSEC
    (1000676002, 24, 12), // VkPhysicalDeviceDataGraphNeuralAcceleratorStatisticsFeaturesARM
    (1000678000, 24, 12), // VkPhysicalDevicePrimitiveRestartIndexFeaturesEXT
    (1000687000, 24, 12), // VkPhysicalDeviceImageTilingControlFeaturesEXT
    (1000689000, 24, 12), // VkPhysicalDeviceCooperativeMatrixDecodeVectorFeaturesNV
];

/// The size of a struct of type `ty` that may extend `VkDeviceCreateInfo` (feature structs
/// included: each also extends `VkPhysicalDeviceFeatures2`), or `None` for one the registry above
/// does not know.
pub fn device_create_info_extender(ty: vk::StructureType) -> Option<usize> {
    let at = DEVICE_CREATE_INFO_EXTENDERS
        .binary_search_by_key(&ty.as_raw(), |&(t, _, _)| t)
        .ok()?;
    let (_, wide, narrow) = DEVICE_CREATE_INFO_EXTENDERS[at];
    Some(if cfg!(target_pointer_width = "64") {
        wide as usize
    } else {
        narrow as usize
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::size_of;

    #[test]
    fn sorted_and_unique() {
        assert!(DEVICE_CREATE_INFO_EXTENDERS
            .windows(2)
            .all(|w| w[0].0 < w[1].0));
    }

    /// The rows ash also defines agree with ash's layout: the registry was read right.
    #[test]
    fn rows_agree_with_ash() {
        macro_rules! check {
            ($($t:ident),* $(,)?) => {$(
                assert_eq!(
                    device_create_info_extender(
                        <vk::$t<'static> as vk::TaggedStructure>::STRUCTURE_TYPE
                    ),
                    Some(size_of::<vk::$t<'static>>()),
                    stringify!($t)
                );
            )*};
        }
        check![
            PhysicalDeviceFeatures2,
            DeviceGroupDeviceCreateInfo,
            DevicePrivateDataCreateInfo,
            DeviceMemoryOverallocationCreateInfoAMD,
            DeviceDiagnosticsConfigCreateInfoNV,
            DeviceDeviceMemoryReportCreateInfoEXT,
            DeviceQueueShaderCoreControlCreateInfoARM,
            PhysicalDeviceVulkan11Features,
            PhysicalDeviceVulkan12Features,
            PhysicalDeviceVulkan13Features,
            PhysicalDeviceMultiviewFeatures,
            PhysicalDevice16BitStorageFeatures,
            PhysicalDeviceDescriptorIndexingFeatures,
            PhysicalDeviceDynamicRenderingFeatures,
            PhysicalDeviceSynchronization2Features,
            PhysicalDeviceMaintenance4Features,
            PhysicalDeviceMaintenance5FeaturesKHR,
            PhysicalDeviceDynamicRenderingLocalReadFeaturesKHR,
            PhysicalDeviceExtendedDynamicState3FeaturesEXT,
            PhysicalDeviceRobustness2FeaturesEXT,
            PhysicalDeviceMeshShaderFeaturesEXT,
            PhysicalDeviceRayTracingPipelineFeaturesKHR,
            PhysicalDeviceAccelerationStructureFeaturesKHR,
            PhysicalDeviceShaderObjectFeaturesEXT,
            PhysicalDeviceDescriptorBufferFeaturesEXT,
            PhysicalDeviceHostImageCopyFeaturesEXT,
            PhysicalDeviceFragmentDensityMapFeaturesEXT,
            PhysicalDeviceFragmentDensityMap2FeaturesEXT,
            PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM,
            PhysicalDeviceFragmentShadingRateFeaturesKHR,
            PhysicalDeviceFragmentShadingRateEnumsFeaturesNV,
            PhysicalDeviceShadingRateImageFeaturesNV,
            PhysicalDeviceCooperativeMatrixFeaturesKHR,
            PhysicalDeviceLineRasterizationFeaturesKHR,
            PhysicalDeviceVertexAttributeDivisorFeaturesKHR,
            PhysicalDeviceIndexTypeUint8FeaturesKHR,
            PhysicalDeviceShaderEnqueueFeaturesAMDX,
            PhysicalDeviceExternalFormatResolveFeaturesANDROID,
            PhysicalDevicePortabilitySubsetFeaturesKHR,
            PhysicalDeviceCudaKernelLaunchFeaturesNV,
            PhysicalDeviceRayTracingMotionBlurFeaturesNV,
            PhysicalDeviceDisplacementMicromapFeaturesNV,
            PhysicalDeviceImageProcessing2FeaturesQCOM,
            PhysicalDeviceShaderCoreBuiltinsFeaturesARM,
            PhysicalDevicePerStageDescriptorSetFeaturesNV,
            PhysicalDeviceCubicClampFeaturesQCOM,
            PhysicalDeviceShaderAtomicFloat2FeaturesEXT,
            PhysicalDeviceGraphicsPipelineLibraryFeaturesEXT,
            PhysicalDeviceSwapchainMaintenance1FeaturesEXT,
            PhysicalDeviceRayTracingMaintenance1FeaturesKHR,
            PhysicalDeviceVideoMaintenance1FeaturesKHR,
            PhysicalDeviceShaderFloatControls2FeaturesKHR,
            PhysicalDeviceShaderExpectAssumeFeaturesKHR,
            PhysicalDeviceShaderSubgroupRotateFeaturesKHR,
            PhysicalDevicePipelineProtectedAccessFeaturesEXT,
            PhysicalDevicePipelineRobustnessFeaturesEXT,
            PhysicalDeviceGlobalPriorityQueryFeaturesKHR,
            PhysicalDeviceRawAccessChainsFeaturesNV,
            PhysicalDeviceShaderAtomicFloat16VectorFeaturesNV,
        ];
    }

    /// Newer than ash: Vulkan 1.4's core features and the maintenance structs, by their registry
    /// numbers (sType, all-`VkBool32` bodies after the 16-byte header, padded to 8).
    #[test]
    fn newer_structs_are_known() {
        for (ty, size) in [
            (55, 104),           // VkPhysicalDeviceVulkan14Features: 22 booleans
            (1_000_545_000, 24), // VkPhysicalDeviceMaintenance6Features
            (1_000_562_000, 24), // VkPhysicalDeviceMaintenance7FeaturesKHR
            (1_000_574_000, 24), // VkPhysicalDeviceMaintenance8FeaturesKHR
            (1_000_584_000, 24), // VkPhysicalDeviceMaintenance9FeaturesKHR
        ] {
            assert_eq!(
                device_create_info_extender(vk::StructureType::from_raw(ty)),
                Some(size),
                "{ty}"
            );
        }
        assert_eq!(
            device_create_info_extender(vk::StructureType::from_raw(1_000_900_001)),
            None
        );
    }
}

// The SIMD instruction sets this CPU offers to the loops compiled for several
// (the native sweep, the CPU TSDF integrator): each such loop is built for the
// x86-64 baseline, AVX2 + FMA and AVX-512, and runs the best the CPU has.
// FM_NO_AVX512 in the environment caps the choice at AVX2 (for comparisons).
#ifndef FISHEYE_MAPPING_CORE_COMMON_CPU_FEATURES_H_
#define FISHEYE_MAPPING_CORE_COMMON_CPU_FEATURES_H_

namespace fisheye_mapping {

enum class SimdLevel { kBaseline, kAvx2, kAvx512 };

// Detected once per process.
SimdLevel cpuSimdLevel();

// "baseline", "avx2+fma", "avx512".
const char* simdLevelName(SimdLevel level);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_CPU_FEATURES_H_

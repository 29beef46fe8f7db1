// Host-device qualifiers, so that the math shared by the CPU and CUDA backends is
// written once and compiled by both g++ and nvcc.
#pragma once

#if defined(__CUDACC__)
#define CATGS_HD __host__ __device__
#define CATGS_INLINE __host__ __device__ __forceinline__
#else
#define CATGS_HD
#define CATGS_INLINE inline
#endif

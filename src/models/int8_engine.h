// The CPU's int8 machinery: LibTorch's quantized engine, and whether activations must take 7 bits.
#pragma once

#include <string>

namespace geo {

// LibTorch's quantized engine for int8 convolutions and products, selected process-wide: oneDNN's
// where this LibTorch has it, else x86's, FBGEMM's or QNNPACK's; "" when it has none.
std::string select_int8_engine();

// Whether quantized activations take 7 bits (0..127) instead of 8: on x86 CPUs without an 8-bit dot
// product instruction (AVX-512 VNNI or AVX-VNNI; AMX CPUs have VNNI), where the int8 convolutions add
// pairs of u8 x s8 products in 16 bits (vpmaddubsw), which saturates beyond 7-bit activations (as
// PyTorch's reduce_range). Measured on a 2-core AVX2 EPYC: 8 bits there put a DepthNet's int8 error
// at 0.16 of its disparity's spread.
bool int8_reduced_range();

}  // namespace geo

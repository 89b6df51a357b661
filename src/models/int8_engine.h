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

// Whether 1x1 int8 convolutions are packed as dilated ones (dilation 2: the same arithmetic for a
// 1x1 kernel) so that oneDNN runs them with its general kernel instead of its 1x1 one: on CPUs with
// AMX, oneDNN's AMX 1x1 int8 kernel writes outside its buffers for some small images (oneDNN 2.6, as
// in LibTorch 1.13: 64 -> 128 channels on 1x27 ... 1x48 pixels, 2048 -> 512 on 4x12), corrupting
// the heap (Int8.EverySizeAndCalibrationIsMemorySafe). The general kernel gives the same bytes.
bool int8_dilated_1x1();

}  // namespace geo

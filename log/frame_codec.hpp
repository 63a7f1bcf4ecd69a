// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Camera-frame encoding and decoding for the session log, on libpng and libwebp directly.
//
// Why not OpenCV: its imgcodecs module drags ~140 shared libraries (GDAL, poppler, HDF5) into
// every program that stores or reads a frame. This file calls the same two libraries OpenCV 4.6
// calls, with the same settings, so the bytes written are identical to what
//   cv::imencode(".png", img)                                    -> encode_png(img)
//   cv::imencode(".png", img, {cv::IMWRITE_PNG_COMPRESSION, n})  -> encode_png(img, n)
//   cv::imencode(".webp", img, {cv::IMWRITE_WEBP_QUALITY, 101})  -> encode_webp_lossless(img)
// produced, and decoding gives the pixels of cv::imdecode with IMREAD_UNCHANGED
// (ReadMode::kUnchanged) or IMREAD_GRAYSCALE (ReadMode::kGray8). Logs written before and after
// the switch are therefore indistinguishable. The one deliberate difference: alpha is always
// dropped (OpenCV returns 4 channels for images with alpha under IMREAD_UNCHANGED); camera
// frames never carry alpha.
//
// No function throws; failures are values (core/result.hpp).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/result.hpp"

namespace imucal::log {

/// An uncompressed image: rows stored top to bottom without padding.
struct Image {
  int width = 0;
  int height = 0;
  int channels = 1;  // 1 = gray, 3 = B,G,R interleaved (OpenCV's order)
  int depth = 8;     // bits per sample: 8 or 16; 16-bit samples are in host byte order
  std::vector<std::uint8_t> data;

  std::size_t bytes_per_sample() const { return depth == 16 ? 2 : 1; }
  std::size_t row_bytes() const {
    return static_cast<std::size_t>(std::max(width, 0)) * static_cast<std::size_t>(std::max(channels, 0)) *
           bytes_per_sample();
  }
  bool empty() const { return width <= 0 || height <= 0; }

  /// A zero-filled image of the given shape (negative sizes give an empty image).
  static Image zeros(int width, int height, int channels = 1, int depth = 8);
};

enum class ImageFormat { kUnknown, kPng, kWebp };

/// What a decoder hands back.
enum class ReadMode {
  /// Keep the stored depth (8 or 16 bits); gray stays 1 channel, colour and palette images
  /// become 3-channel BGR, alpha is dropped. Like cv::IMREAD_UNCHANGED for images without alpha.
  kUnchanged,
  /// Always 8-bit gray, with exactly the pixel values of cv::IMREAD_GRAYSCALE: 16-bit samples
  /// keep their high byte; colour is weighted (libpng's 0.299/0.587/0.114 for PNG, OpenCV's
  /// cvtColor(BGR2GRAY) fixed-point formula for WebP).
  kGray8,
};

struct ImageSize {
  int width = 0;
  int height = 0;
};

/// PNG compression setting matching cv::imencode(".png", img) without parameters: the Sub row
/// filter, zlib level 1, Z_RLE strategy. Fast; files are ~10-30% larger than level 9.
inline constexpr int kPngFast = -1;

/// Encodes 8- or 16-bit gray or BGR as PNG. compression_level 0-9 selects the zlib level with
/// libpng's adaptive row filters and the default zlib strategy, like IMWRITE_PNG_COMPRESSION;
/// kPngFast is OpenCV's parameterless default. No ancillary chunks are written.
[[nodiscard]] Result<std::vector<std::uint8_t>> encode_png(const Image& image,
                                                           int compression_level = kPngFast);

/// Encodes 8-bit gray or BGR as lossless WebP (WebPEncodeLosslessBGR). Gray is replicated to
/// three channels first, because WebP has no gray mode; kGray8 decoding recovers it exactly.
[[nodiscard]] Result<std::vector<std::uint8_t>> encode_webp_lossless(const Image& image);

/// Decodes a PNG: any bit depth, colour type and interlacing libpng reads; see ReadMode.
/// Damaged or truncated data gives Errc::kCorrupt with libpng's message. Both decoders refuse
/// (Errc::kUnsupported) images whose pixels would exceed 256 MiB, so that a damaged header
/// cannot make them allocate gigabytes.
[[nodiscard]] Result<Image> decode_png(std::span<const std::uint8_t> bytes,
                                       ReadMode mode = ReadMode::kUnchanged);

/// Decodes a WebP (lossy or lossless) to BGR, or to gray under kGray8.
[[nodiscard]] Result<Image> decode_webp(std::span<const std::uint8_t> bytes,
                                        ReadMode mode = ReadMode::kUnchanged);

/// Recognises PNG and WebP by their signatures; does not check anything further.
ImageFormat sniff_format(std::span<const std::uint8_t> bytes);

/// Decodes a PNG or WebP, chosen by signature; anything else is Errc::kUnsupported.
[[nodiscard]] Result<Image> decode_image(std::span<const std::uint8_t> bytes,
                                         ReadMode mode = ReadMode::kUnchanged);

/// Width and height from a PNG's IHDR chunk, without decompressing anything.
[[nodiscard]] Result<ImageSize> png_dimensions(std::span<const std::uint8_t> bytes);

/// Width and height of a PNG or WebP from its headers, without decoding pixels.
[[nodiscard]] Result<ImageSize> image_dimensions(std::span<const std::uint8_t> bytes);

}  // namespace imucal::log

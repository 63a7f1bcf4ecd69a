// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "log/frame_codec.hpp"

namespace imucal::log {
namespace {

using ::testing::HasSubstr;
using Bytes = std::vector<std::uint8_t>;

// Hand-made PNGs (Python's zlib, not libpng), so decoding is checked against an independent
// writer: 2x1 16-bit gray holding 0x1234 and 0xABCD (big-endian on disk), and 2x1 8-bit RGB
// holding (R,G,B) = (10,20,30) and (200,100,0).
const Bytes kGray16Png = {0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48,
                          0x44, 0x52, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, 0x01, 0x10, 0x00, 0x00, 0x00,
                          0x00, 0x81, 0xd9, 0xfc, 0x15, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x44, 0x41, 0x54, 0x78,
                          0x9c, 0x63, 0x10, 0x32, 0x59, 0x7d, 0x16, 0x00, 0x03, 0x0c, 0x01, 0xbf, 0x6e, 0xb9,
                          0xc6, 0x5d, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
const Bytes kRgb8Png = {0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d,
                        0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, 0x01,
                        0x08, 0x02, 0x00, 0x00, 0x00, 0x7b, 0x40, 0xe8, 0xdd, 0x00, 0x00, 0x00,
                        0x0f, 0x49, 0x44, 0x41, 0x54, 0x78, 0x9c, 0x63, 0xe0, 0x12, 0x91, 0x3b,
                        0x91, 0xc2, 0x00, 0x00, 0x04, 0x3f, 0x01, 0x69, 0x82, 0xbc, 0xf3, 0x00,
                        0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};

// Noise over a gradient: compressible enough to exercise the row filters, irregular enough
// that a swapped byte or channel cannot go unnoticed. Odd sizes catch stride mistakes.
Image pattern(int width, int height, int channels, int depth, std::uint32_t seed = 1) {
  Image image = Image::zeros(width, height, channels, depth);
  for (std::size_t i = 0; i < image.data.size(); ++i) {
    seed = seed * 1664525u + 1013904223u;
    image.data[i] = static_cast<std::uint8_t>(i / 7 + (seed >> 28));
  }
  return image;
}

void expect_same(const Image& a, const Image& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.channels, b.channels);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_TRUE(a.data == b.data) << "pixels differ";
}

// The encoded bytes, or an empty buffer (and a test failure) if encoding failed.
Bytes encoded(const Result<Bytes>& result) {
  if (result.ok()) return result.value();
  ADD_FAILURE() << result.error().message;
  return {};
}

std::uint16_t sample16(const Image& image, std::size_t i) {
  std::uint16_t v = 0;
  std::memcpy(&v, image.data.data() + 2 * i, 2);
  return v;
}

TEST(FrameCodec, PngRoundTripsGrayAndBgrAtEveryDepthAndLevel) {
  for (const auto& [channels, depth] :
       {std::pair{1, 8}, std::pair{1, 16}, std::pair{3, 8}, std::pair{3, 16}}) {
    const Image image = pattern(37, 23, channels, depth);
    for (int level : {kPngFast, 0, 1, 6, 9}) {
      SCOPED_TRACE("channels " + std::to_string(channels) + " depth " + std::to_string(depth) + " level " +
                   std::to_string(level));
      auto png = encode_png(image, level);
      ASSERT_TRUE(png.ok()) << png.error().message;
      EXPECT_EQ(sniff_format(*png), ImageFormat::kPng);
      auto back = decode_png(*png);
      ASSERT_TRUE(back.ok()) << back.error().message;
      expect_same(*back, image);
      auto size = png_dimensions(*png);
      ASSERT_TRUE(size.ok());
      EXPECT_EQ(size->width, 37);
      EXPECT_EQ(size->height, 23);
    }
  }
}

TEST(FrameCodec, Png16IsBigEndianOnDiskAndHostOrderInMemory) {
  auto image = decode_png(kGray16Png);
  ASSERT_TRUE(image.ok()) << image.error().message;
  ASSERT_EQ(image->depth, 16);
  ASSERT_EQ(image->channels, 1);
  EXPECT_EQ(sample16(*image, 0), 0x1234);
  EXPECT_EQ(sample16(*image, 1), 0xABCD);
  // Our own encoder must write what the independent file holds; checked through the decoder
  // that was just validated above.
  auto png = encode_png(*image, 9);
  ASSERT_TRUE(png.ok());
  auto back = decode_png(*png);
  ASSERT_TRUE(back.ok());
  expect_same(*back, *image);
  // Gray8 keeps the high byte, as cv::IMREAD_GRAYSCALE does.
  auto gray = decode_png(kGray16Png, ReadMode::kGray8);
  ASSERT_TRUE(gray.ok());
  EXPECT_EQ(gray->depth, 8);
  EXPECT_EQ(gray->data, (Bytes{0x12, 0xAB}));
}

TEST(FrameCodec, ColourPngDecodesToBgrAndToOpenCvGray) {
  auto bgr = decode_png(kRgb8Png);
  ASSERT_TRUE(bgr.ok()) << bgr.error().message;
  EXPECT_EQ(bgr->channels, 3);
  EXPECT_EQ(bgr->data, (Bytes{30, 20, 10, 0, 100, 200}));
  // Values cv::imdecode(..., IMREAD_GRAYSCALE) returns for this file (libpng's weighting).
  auto gray = decode_png(kRgb8Png, ReadMode::kGray8);
  ASSERT_TRUE(gray.ok());
  EXPECT_EQ(gray->data, (Bytes{18, 118}));
}

TEST(FrameCodec, WebpOfGrayDecodesBackToTheSameGray) {
  const Image gray = pattern(41, 17, 1, 8);
  auto webp = encode_webp_lossless(gray);
  ASSERT_TRUE(webp.ok()) << webp.error().message;
  EXPECT_EQ(sniff_format(*webp), ImageFormat::kWebp);
  auto back = decode_webp(*webp, ReadMode::kGray8);
  ASSERT_TRUE(back.ok()) << back.error().message;
  expect_same(*back, gray);
  // Unchanged: the three replicated channels WebP actually stores.
  auto bgr = decode_image(*webp);
  ASSERT_TRUE(bgr.ok());
  ASSERT_EQ(bgr->channels, 3);
  for (std::size_t i = 0; i < gray.data.size(); ++i) {
    ASSERT_EQ(bgr->data[3 * i], gray.data[i]);
    ASSERT_EQ(bgr->data[3 * i + 1], gray.data[i]);
    ASSERT_EQ(bgr->data[3 * i + 2], gray.data[i]);
  }
  auto size = image_dimensions(*webp);
  ASSERT_TRUE(size.ok());
  EXPECT_EQ(size->width, 41);
  EXPECT_EQ(size->height, 17);
}

TEST(FrameCodec, WebpRoundTripsBgrAndGraysLikeOpenCv) {
  const Image bgr = pattern(29, 31, 3, 8, 7);
  auto webp = encode_webp_lossless(bgr);
  ASSERT_TRUE(webp.ok());
  auto back = decode_image(*webp);
  ASSERT_TRUE(back.ok());
  expect_same(*back, bgr);
  // (B,G,R) = (30,20,10) and (0,100,200): cv::cvtColor(BGR2GRAY) gives 18 and 119 (not libpng's 118).
  Image two = Image::zeros(2, 1, 3);
  two.data = {30, 20, 10, 0, 100, 200};
  auto gray = decode_webp(encoded(encode_webp_lossless(two)), ReadMode::kGray8);
  ASSERT_TRUE(gray.ok());
  EXPECT_EQ(gray->data, (Bytes{18, 119}));
}

// What cv::imencode (OpenCV 4.6, Debian 12: libpng 1.6.39, zlib 1.2.13, libwebp 1.2.4) writes for
// checkerboard() with no parameters, with IMWRITE_PNG_COMPRESSION 9, and with
// IMWRITE_WEBP_QUALITY 101. Logs must not change when frames stop going through OpenCV. The
// image is big enough for the zlib strategy and row filter to show in the bytes. Another zlib
// or libwebp version may legitimately compress differently; then regenerate these.
const Bytes kOpenCvPngDefault = {
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00,
    0x00, 0x00, 0x10, 0x00, 0x00, 0x00, 0x08, 0x08, 0x00, 0x00, 0x00, 0x00, 0xd5, 0x1d, 0x20, 0x4b, 0x00,
    0x00, 0x00, 0x60, 0x49, 0x44, 0x41, 0x54, 0x08, 0x1d, 0x05, 0xc1, 0x89, 0x01, 0x82, 0x30, 0x14, 0x44,
    0xc1, 0xb7, 0x3f, 0xcd, 0x78, 0xd4, 0x24, 0x02, 0xf6, 0x85, 0x46, 0xba, 0x89, 0x35, 0x65, 0xd7, 0x19,
    0x5d, 0x24, 0x0e, 0x55, 0x96, 0x0a, 0x5d, 0xb3, 0xe9, 0x6e, 0x71, 0x80, 0x9e, 0x45, 0x3e, 0xc5, 0xd4,
    0xb5, 0xac, 0x77, 0x91, 0x8d, 0xa9, 0x6e, 0x45, 0x37, 0x39, 0xe7, 0x6c, 0x73, 0x8b, 0x72, 0x3a, 0xa5,
    0x1f, 0x93, 0x17, 0xa6, 0x2b, 0x59, 0xd3, 0xa2, 0x01, 0xde, 0x24, 0x7f, 0x5d, 0x2c, 0x10, 0x0d, 0xc2,
    0xee, 0xa8, 0x5b, 0x59, 0x5b, 0xd0, 0x90, 0xd9, 0x43, 0xba, 0x1b, 0x0f, 0xca, 0x7f, 0xc0, 0x02, 0x37,
    0xd2, 0xaa, 0xe2, 0x1d, 0x29, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
const Bytes kOpenCvPngLevel9 = {
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00,
    0x00, 0x00, 0x10, 0x00, 0x00, 0x00, 0x08, 0x08, 0x00, 0x00, 0x00, 0x00, 0xd5, 0x1d, 0x20, 0x4b, 0x00,
    0x00, 0x00, 0x59, 0x49, 0x44, 0x41, 0x54, 0x08, 0xd7, 0x15, 0x4d, 0x81, 0x09, 0xc3, 0x00, 0x0c, 0x52,
    0xd3, 0x63, 0x7a, 0x55, 0x29, 0xec, 0xaf, 0xc1, 0xee, 0xd9, 0x4d, 0xd1, 0xda, 0x40, 0x22, 0xa8, 0x51,
    0x9e, 0x24, 0xbe, 0x54, 0x2e, 0x05, 0x3f, 0xee, 0x68, 0xd0, 0xc9, 0x06, 0x20, 0x82, 0xd9, 0xc3, 0x32,
    0x29, 0x64, 0xb0, 0xe4, 0x12, 0x22, 0x60, 0x2d, 0xec, 0x65, 0xc8, 0x88, 0x7f, 0x2c, 0x3e, 0x70, 0xff,
    0x93, 0x3b, 0x13, 0x25, 0x82, 0xbb, 0x34, 0xdf, 0xe3, 0xa3, 0x89, 0x94, 0x5d, 0xdd, 0xa9, 0xe1, 0x65,
    0xdb, 0x52, 0x00, 0x5a, 0xd8, 0xac, 0x07, 0x58, 0x7d, 0x2f, 0xff, 0x8c, 0x06, 0xef, 0x0c, 0x00, 0x00,
    0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
const Bytes kOpenCvWebp = {0x52, 0x49, 0x46, 0x46, 0x74, 0x00, 0x00, 0x00, 0x57, 0x45, 0x42, 0x50, 0x56, 0x50,
                           0x38, 0x4c, 0x68, 0x00, 0x00, 0x00, 0x2f, 0x0f, 0xc0, 0x01, 0x00, 0x3f, 0x40, 0x90,
                           0x6d, 0x93, 0xda, 0x1c, 0xfb, 0xa6, 0xd3, 0x20, 0xc8, 0xb6, 0x49, 0x6d, 0x8e, 0x7d,
                           0xd3, 0x11, 0x64, 0xdb, 0xa4, 0x36, 0xc7, 0xbe, 0xe9, 0xe6, 0x3f, 0xb6, 0x05, 0x80,
                           0xff, 0x2a, 0x95, 0x0a, 0x18, 0xd4, 0xd6, 0x96, 0x56, 0xd8, 0xfe, 0x25, 0xf8, 0xa5,
                           0x00, 0x52, 0x60, 0x52, 0x01, 0x29, 0x30, 0x29, 0x80, 0x14, 0xf8, 0x81, 0x88, 0xfe,
                           0x07, 0xba, 0xfe, 0x18, 0x8a, 0x59, 0xdc, 0xea, 0x86, 0x93, 0x9e, 0x36, 0x3d, 0x37,
                           0x8e, 0x79, 0x81, 0x2a, 0x40, 0xf9, 0xc3, 0xba, 0x29, 0x56, 0xf0, 0xef, 0xb0, 0x52,
                           0x02, 0xc1, 0xdb, 0x04, 0xc7, 0x3c, 0x5c, 0x6c, 0x9e, 0x47, 0xd8, 0x76};

// A 16x8 noisy checkerboard of 4-pixel squares, like a tiny rendered calibration target.
Image checkerboard() {
  Image image = Image::zeros(16, 8);
  std::uint32_t seed = 1;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      seed = seed * 1664525u + 1013904223u;
      image.data[y * image.width + x] =
          static_cast<std::uint8_t>(((x / 4 + y / 4) % 2 ? 200 : 40) + (seed >> 30));
    }
  }
  return image;
}

TEST(FrameCodec, WritesTheSameBytesAsOpenCv) {
  const Image image = checkerboard();
  EXPECT_EQ(encoded(encode_png(image)), kOpenCvPngDefault);
  EXPECT_EQ(encoded(encode_png(image, 9)), kOpenCvPngLevel9);
  EXPECT_EQ(encoded(encode_webp_lossless(image)), kOpenCvWebp);
}

TEST(FrameCodec, TruncatedOrDamagedDataIsAnErrorNotACrash) {
  const Image image = pattern(24, 16, 1, 8);
  for (const Bytes& full : {encoded(encode_png(image, 9)), encoded(encode_png(pattern(24, 16, 1, 16))),
                            encoded(encode_webp_lossless(image))}) {
    for (std::size_t n = 0; n < full.size(); ++n) {
      auto cut = decode_image(std::span(full.data(), n));
      ASSERT_FALSE(cut.ok()) << "a " << n << "-byte prefix of " << full.size() << " bytes was accepted";
    }
    for (std::size_t i = 8; i < full.size(); i += 3) {  // any outcome is fine, as long as it is a value
      Bytes bad = full;
      bad[i] ^= 0x5a;
      auto result = decode_image(bad, ReadMode::kGray8);
      if (result.ok()) {
        EXPECT_EQ(result->data.size(), image.data.size());
      }
    }
  }
  Bytes png = encoded(encode_png(image, 9));
  ASSERT_GT(png.size(), 40u);
  png[png.size() - 20] ^= 0xff;  // inside IDAT: its CRC no longer matches
  auto damaged = decode_png(png);
  ASSERT_FALSE(damaged.ok());
  EXPECT_EQ(damaged.error().code, Errc::kCorrupt);
  EXPECT_THAT(damaged.error().message, HasSubstr("PNG decoding failed: "));
}

TEST(FrameCodec, UnknownSignaturesAreRejected) {
  const Bytes jpeg = {0xff, 0xd8, 0xff, 0xe0, 0x00, 0x10, 'J', 'F', 'I', 'F', 0x00, 0x01, 0x01};
  const Bytes wave = {'R', 'I', 'F', 'F', 0x24, 0x00, 0x00, 0x00, 'W', 'A', 'V', 'E', 'f', 'm', 't', ' '};
  for (const Bytes& bytes : {jpeg, wave, Bytes{}, Bytes{0x89, 'P', 'N'}}) {
    EXPECT_EQ(sniff_format(bytes), ImageFormat::kUnknown);
    auto image = decode_image(bytes);
    ASSERT_FALSE(image.ok());
    EXPECT_EQ(image.error().code, Errc::kUnsupported);
    EXPECT_EQ(image.error().message, "not a PNG or WebP image");
    EXPECT_FALSE(image_dimensions(bytes).ok());
  }
  EXPECT_FALSE(decode_png(encoded(encode_webp_lossless(pattern(4, 4, 1, 8)))).ok());
  EXPECT_FALSE(decode_webp(kRgb8Png).ok());
}

TEST(FrameCodec, EncodersRejectMalformedImages) {
  Image short_data = pattern(8, 8, 1, 8);
  short_data.data.pop_back();
  Image two_channels = Image::zeros(8, 8, 3);
  two_channels.channels = 2;
  Image twelve_bits = Image::zeros(8, 8);
  twelve_bits.depth = 12;
  for (const Image& bad : {short_data, two_channels, twelve_bits, Image{}}) {
    auto png = encode_png(bad);
    ASSERT_FALSE(png.ok());
    EXPECT_EQ(png.error().code, Errc::kInvalidArgument);
    EXPECT_FALSE(encode_webp_lossless(bad).ok());
  }
  auto webp16 = encode_webp_lossless(pattern(8, 8, 1, 16));
  ASSERT_FALSE(webp16.ok());
  EXPECT_THAT(webp16.error().message, HasSubstr("8-bit"));
  EXPECT_FALSE(encode_png(pattern(8, 8, 1, 8), 10).ok());
  EXPECT_FALSE(encode_png(pattern(8, 8, 1, 8), -2).ok());
}

}  // namespace
}  // namespace imucal::log

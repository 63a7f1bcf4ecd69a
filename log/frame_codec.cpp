// SPDX-License-Identifier: BSD-3-Clause
#include "log/frame_codec.hpp"

#include <png.h>
#include <webp/decode.h>
#include <webp/encode.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <string>

namespace imucal::log {
namespace {

constexpr std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
constexpr bool kLittleEndian = std::endian::native == std::endian::little;
// A damaged header can claim gigapixels; decoders refuse to allocate more than this. It is far
// above any camera frame (a 16-bit 8K x 8K image is 128 MiB).
constexpr std::size_t kMaxImageBytes = std::size_t{256} << 20;

std::string shape(const Image& image) {
  return std::to_string(image.width) + "x" + std::to_string(image.height) + " with " +
         std::to_string(image.channels) + " channel(s) of " + std::to_string(image.depth) + " bits";
}

Status check_image(const Image& image, const char* format) {
  const std::string prefix = std::string("cannot encode ") + format + ": ";
  if (image.empty()) return make_error(Errc::kInvalidArgument, prefix + "the image is empty");
  if (image.channels != 1 && image.channels != 3) {
    return make_error(Errc::kInvalidArgument, prefix + "the image has " + std::to_string(image.channels) +
                                                  " channels; only 1 (gray) and 3 (BGR) are supported");
  }
  if (image.depth != 8 && image.depth != 16) {
    return make_error(Errc::kInvalidArgument, prefix + "samples of " + std::to_string(image.depth) +
                                                  " bits are not supported; use 8 or 16");
  }
  const std::size_t expected = image.row_bytes() * static_cast<std::size_t>(image.height);
  if (image.data.size() != expected) {
    return make_error(Errc::kInvalidArgument, prefix + "the image holds " +
                                                  std::to_string(image.data.size()) + " bytes, but " +
                                                  shape(image) + " needs " + std::to_string(expected));
  }
  return {};
}

// Allocation for decoders: bounded, and std::bad_alloc becomes a value instead of escaping.
Result<Image> blank_image(int width, int height, int channels, int depth, const char* format) {
  const Image probe{width, height, channels, depth, {}};
  if (probe.empty() || probe.row_bytes() * static_cast<std::size_t>(height) > kMaxImageBytes) {
    return make_error(Errc::kUnsupported, std::string(format) + " image of " + shape(probe) +
                                              " is empty or larger than this decoder accepts");
  }
  try {
    return Image::zeros(width, height, channels, depth);
  } catch (const std::bad_alloc&) {
    return make_error(Errc::kInternal,
                      std::string("out of memory decoding a ") + format + " of " + shape(probe));
  }
}

// ---- libpng -------------------------------------------------------------------------------
// libpng reports errors by longjmp to the last setjmp. Jumping over a frame that holds C++
// objects with destructors is undefined, so each function that calls setjmp below holds only
// raw pointers and plain values; every owning object lives in its caller.

struct PngContext {
  char message[200] = "unknown error";  // libpng's last error
  const std::uint8_t* in = nullptr;     // decoding: the input and the read position
  std::size_t in_size = 0;
  std::size_t in_pos = 0;
  std::vector<std::uint8_t>* out = nullptr;  // encoding: grows as libpng writes
};

[[noreturn]] void png_on_error(png_structp png, png_const_charp message) {
  auto* ctx = static_cast<PngContext*>(png_get_error_ptr(png));
  std::snprintf(ctx->message, sizeof ctx->message, "%s", message);
  png_longjmp(png, 1);
}

// Warnings (e.g. a bad CRC in an ancillary chunk, which libpng then skips) do not affect the
// pixels; OpenCV prints them to stderr, we stay quiet.
void png_on_warning(png_structp /*png*/, png_const_charp /*message*/) {}

void png_on_read(png_structp png, png_bytep dst, std::size_t size) {
  auto* ctx = static_cast<PngContext*>(png_get_io_ptr(png));
  if (size > ctx->in_size - ctx->in_pos) png_error(png, "the data ends early (truncated)");
  std::memcpy(dst, ctx->in + ctx->in_pos, size);
  ctx->in_pos += size;
}

void png_on_write(png_structp png, png_bytep data, std::size_t size) {
  auto* ctx = static_cast<PngContext*>(png_get_io_ptr(png));
  bool out_of_memory = false;
  try {
    ctx->out->insert(ctx->out->end(), data, data + size);
  } catch (const std::bad_alloc&) {
    out_of_memory = true;  // png_error must not be called from inside the handler
  }
  if (out_of_memory) png_error(png, "out of memory");
}

void png_on_flush(png_structp /*png*/) {}

// The calls, their order and their settings repeat OpenCV 4.6's PngEncoder::write, which is
// what makes the output byte-identical.
bool png_write_all(png_structp png, png_infop info, PngContext* ctx, const Image& image, int level) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_write_fn(png, ctx, png_on_write, png_on_flush);
  if (level == kPngFast) {
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
    png_set_compression_level(png, Z_BEST_SPEED);
    png_set_compression_strategy(png, Z_RLE);
  } else {
    png_set_compression_level(png, level);
    png_set_compression_strategy(png, Z_DEFAULT_STRATEGY);
  }
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height),
               image.depth, image.channels == 1 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_set_bgr(png);                      // memory is BGR, PNG is RGB
  if (kLittleEndian) png_set_swap(png);  // PNG stores 16-bit samples big-endian
  const std::uint8_t* row = image.data.data();
  for (int y = 0; y < image.height; ++y, row += image.row_bytes()) png_write_row(png, row);
  png_write_end(png, info);
  return true;
}

struct PngLayout {
  int width = 0;
  int height = 0;
  int channels = 0;
  int depth = 0;
  std::size_t row_bytes = 0;
  int passes = 1;
};

// Reads the header and sets up the transformations of OpenCV 4.6's PngDecoder::readData for a
// 1- or 3-channel result, so that the pixels equal cv::imdecode's.
bool png_read_header(png_structp png, png_infop info, ReadMode mode, PngLayout* layout) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_info(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  const int color_type = png_get_color_type(png, info);
  const bool color_in = (color_type & PNG_COLOR_MASK_COLOR) != 0;
  const bool color_out = color_in && mode == ReadMode::kUnchanged;
  if (bit_depth == 16 && mode == ReadMode::kGray8) {
    png_set_strip_16(png);  // the high byte, as OpenCV does (no rounding)
  } else if (kLittleEndian) {
    png_set_swap(png);
  }
  png_set_strip_alpha(png);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (!color_in && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (color_out) {
    png_set_bgr(png);
  } else {
    png_set_rgb_to_gray_fixed(png, PNG_ERROR_ACTION_NONE, 29900, 58700);  // 0.299 R + 0.587 G
  }
  layout->passes = png_set_interlace_handling(png);
  png_read_update_info(png, info);
  layout->width = static_cast<int>(png_get_image_width(png, info));
  layout->height = static_cast<int>(png_get_image_height(png, info));
  layout->channels = png_get_channels(png, info);
  layout->depth = png_get_bit_depth(png, info);
  layout->row_bytes = png_get_rowbytes(png, info);
  return true;
}

bool png_read_pixels(png_structp png, png_infop info, const PngLayout& layout, std::uint8_t* pixels) {
  if (setjmp(png_jmpbuf(png))) return false;
  for (int pass = 0; pass < layout.passes; ++pass) {
    for (int y = 0; y < layout.height; ++y) png_read_row(png, pixels + y * layout.row_bytes, nullptr);
  }
  png_read_end(png, info);  // checks the remaining chunks and IEND, as OpenCV does
  return true;
}

// Owns libpng's read state, so that every return path frees it.
struct PngReader {
  png_structp png = nullptr;
  png_infop info = nullptr;
  explicit PngReader(PngContext* ctx)
      : png(png_create_read_struct(PNG_LIBPNG_VER_STRING, ctx, png_on_error, png_on_warning)),
        info(png ? png_create_info_struct(png) : nullptr) {}
  PngReader(const PngReader&) = delete;
  PngReader& operator=(const PngReader&) = delete;
  ~PngReader() { png_destroy_read_struct(&png, &info, nullptr); }
};

Error png_failure(const char* what, const PngContext& ctx) {
  return make_error(Errc::kCorrupt, std::string(what) + " failed: " + ctx.message);
}

std::uint32_t be32(std::span<const std::uint8_t> b, std::size_t i) {
  return (std::uint32_t{b[i]} << 24) | (std::uint32_t{b[i + 1]} << 16) | (std::uint32_t{b[i + 2]} << 8) |
         b[i + 3];
}

}  // namespace

Image Image::zeros(int width, int height, int channels, int depth) {
  Image image{std::max(width, 0), std::max(height, 0), channels, depth, {}};
  image.data.assign(image.row_bytes() * static_cast<std::size_t>(image.height), 0);
  return image;
}

Result<std::vector<std::uint8_t>> encode_png(const Image& image, int compression_level) {
  IMUCAL_TRY(check_image(image, "PNG"));
  if (compression_level < kPngFast || compression_level > 9) {
    return make_error(Errc::kInvalidArgument, "PNG compression level " + std::to_string(compression_level) +
                                                  " is out of range; use 0-9 or kPngFast");
  }
  std::vector<std::uint8_t> out;
  PngContext ctx;
  ctx.out = &out;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &ctx, png_on_error, png_on_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  const bool ok = info && png_write_all(png, info, &ctx, image, compression_level);
  png_destroy_write_struct(&png, &info);
  if (!ok) return make_error(Errc::kInternal, std::string("PNG encoding failed: ") + ctx.message);
  return out;
}

Result<Image> decode_png(std::span<const std::uint8_t> bytes, ReadMode mode) {
  if (sniff_format(bytes) != ImageFormat::kPng) return make_error(Errc::kUnsupported, "not a PNG image");
  PngContext ctx;
  ctx.in = bytes.data();
  ctx.in_size = bytes.size();
  const PngReader reader(&ctx);
  if (!reader.info)
    return make_error(Errc::kInternal, "PNG decoding failed: libpng could not be initialised");
  png_set_read_fn(reader.png, &ctx, png_on_read);

  PngLayout layout;
  if (!png_read_header(reader.png, reader.info, mode, &layout)) return png_failure("PNG decoding", ctx);
  const Image probe{layout.width, layout.height, layout.channels, layout.depth, {}};
  if ((layout.channels != 1 && layout.channels != 3) || (layout.depth != 8 && layout.depth != 16) ||
      layout.row_bytes != probe.row_bytes()) {
    return make_error(Errc::kInternal,
                      "PNG decoding failed: libpng produced an unexpected layout (" + shape(probe) + ")");
  }
  auto image = blank_image(layout.width, layout.height, layout.channels, layout.depth, "PNG");
  if (!image.ok()) return image.error();
  if (!png_read_pixels(reader.png, reader.info, layout, image->data.data()))
    return png_failure("PNG decoding", ctx);
  return image;
}

Result<std::vector<std::uint8_t>> encode_webp_lossless(const Image& image) {
  IMUCAL_TRY(check_image(image, "WebP"));
  if (image.depth != 8)
    return make_error(Errc::kInvalidArgument, "cannot encode WebP: it stores 8-bit samples only");
  if (image.width > WEBP_MAX_DIMENSION || image.height > WEBP_MAX_DIMENSION) {
    return make_error(Errc::kInvalidArgument, "cannot encode WebP: " + shape(image) +
                                                  " exceeds its limit of " +
                                                  std::to_string(WEBP_MAX_DIMENSION) + " pixels per side");
  }
  // WebP has no gray mode; like cv::imencode, replicate gray into B, G and R.
  std::vector<std::uint8_t> expanded;
  if (image.channels == 1) {
    expanded.resize(image.data.size() * 3);
    for (std::size_t i = 0; i < image.data.size(); ++i) std::fill_n(&expanded[3 * i], 3, image.data[i]);
  }
  const std::uint8_t* bgr = image.channels == 1 ? expanded.data() : image.data.data();
  std::uint8_t* out = nullptr;
  const std::size_t size = WebPEncodeLosslessBGR(bgr, image.width, image.height, image.width * 3, &out);
  const std::unique_ptr<std::uint8_t, void (*)(void*)> owned(out, WebPFree);
  if (size == 0 || out == nullptr)
    return make_error(Errc::kInternal, "WebP encoding failed for " + shape(image));
  return std::vector<std::uint8_t>(out, out + size);
}

Result<Image> decode_webp(std::span<const std::uint8_t> bytes, ReadMode mode) {
  if (sniff_format(bytes) != ImageFormat::kWebp) return make_error(Errc::kUnsupported, "not a WebP image");
  int width = 0;
  int height = 0;
  if (!WebPGetInfo(bytes.data(), bytes.size(), &width, &height)) {
    return make_error(Errc::kCorrupt, "WebP decoding failed: the header is damaged or truncated");
  }
  auto bgr = blank_image(width, height, 3, 8, "WebP");
  if (!bgr.ok()) return bgr.error();
  if (!WebPDecodeBGRInto(bytes.data(), bytes.size(), bgr->data.data(), bgr->data.size(),
                         static_cast<int>(bgr->row_bytes()))) {
    return make_error(Errc::kCorrupt, "WebP decoding failed: the image data is damaged or truncated");
  }
  if (mode == ReadMode::kUnchanged) return bgr;
  auto gray = blank_image(width, height, 1, 8, "WebP");
  if (!gray.ok()) return gray.error();
  // OpenCV 4.6's 8-bit cvtColor(BGR2GRAY), bit for bit (checked on all 2^24 colours): 15-bit
  // fixed-point weights, rounded. A replicated gray pixel (B = G = R) comes back unchanged
  // because the weights sum to 2^15.
  const std::uint8_t* p = bgr->data.data();
  for (std::uint8_t& g : gray->data) {
    g = static_cast<std::uint8_t>((3735 * p[0] + 19235 * p[1] + 9798 * p[2] + (1 << 14)) >> 15);
    p += 3;
  }
  return gray;
}

ImageFormat sniff_format(std::span<const std::uint8_t> bytes) {
  if (bytes.size() >= 8 && std::equal(kPngSignature, kPngSignature + 8, bytes.begin()))
    return ImageFormat::kPng;
  if (bytes.size() >= 12 && std::memcmp(bytes.data(), "RIFF", 4) == 0 &&
      std::memcmp(bytes.data() + 8, "WEBP", 4) == 0)
    return ImageFormat::kWebp;
  return ImageFormat::kUnknown;
}

Result<Image> decode_image(std::span<const std::uint8_t> bytes, ReadMode mode) {
  switch (sniff_format(bytes)) {
    case ImageFormat::kPng:
      return decode_png(bytes, mode);
    case ImageFormat::kWebp:
      return decode_webp(bytes, mode);
    case ImageFormat::kUnknown:
      break;
  }
  return make_error(Errc::kUnsupported, "not a PNG or WebP image");
}

Result<ImageSize> png_dimensions(std::span<const std::uint8_t> bytes) {
  if (sniff_format(bytes) != ImageFormat::kPng) return make_error(Errc::kUnsupported, "not a PNG image");
  // The IHDR chunk must come first: length (4), "IHDR", width (4), height (4).
  if (bytes.size() < 24 || std::memcmp(bytes.data() + 12, "IHDR", 4) != 0) {
    return make_error(Errc::kCorrupt, "the PNG header is damaged or truncated: no IHDR chunk");
  }
  const std::uint32_t width = be32(bytes, 16);
  const std::uint32_t height = be32(bytes, 20);
  if (width == 0 || height == 0 || width > PNG_UINT_31_MAX || height > PNG_UINT_31_MAX) {
    return make_error(Errc::kCorrupt, "the PNG header gives an invalid size " + std::to_string(width) + "x" +
                                          std::to_string(height));
  }
  return ImageSize{static_cast<int>(width), static_cast<int>(height)};
}

Result<ImageSize> image_dimensions(std::span<const std::uint8_t> bytes) {
  switch (sniff_format(bytes)) {
    case ImageFormat::kPng:
      return png_dimensions(bytes);
    case ImageFormat::kWebp: {
      ImageSize size;
      if (WebPGetInfo(bytes.data(), bytes.size(), &size.width, &size.height)) return size;
      return make_error(Errc::kCorrupt, "the WebP header is damaged or truncated");
    }
    case ImageFormat::kUnknown:
      break;
  }
  return make_error(Errc::kUnsupported, "not a PNG or WebP image");
}

}  // namespace imucal::log

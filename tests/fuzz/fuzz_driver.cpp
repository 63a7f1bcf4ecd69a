// SPDX-License-Identifier: BSD-3-Clause
// A deterministic driver for libFuzzer-style targets (LLVMFuzzerTestOneInput), so every fuzz
// target runs in the test suite under g++ with the sanitizers of the test build, without
// clang's libFuzzer. It runs each seed input, then a fixed number of inputs mutated from the
// seeds (bit flips, interesting bytes, inserted, deleted, duplicated and truncated ranges,
// splices of two seeds), all drawn from a seeded generator: a failure is reproducible from its
// run number. The same target sources link against libFuzzer for open-ended fuzzing
// (docs/fuzzing.md).
//
//   fuzz_<name> [--runs N] [--seed S] [--max-len BYTES] [--last-input FILE] SEED_FILE_OR_DIR...
//
// --last-input writes each input to FILE before it runs: after a crash, a hang or a kill, FILE
// holds the input that did it.
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

using Bytes = std::vector<std::uint8_t>;

struct Options {
  long runs = 20000;
  std::uint64_t seed = 1;
  std::size_t max_len = 1 << 16;
  std::string last_input;
  std::vector<std::string> inputs;
};

bool parse_args(int argc, char** argv, Options& options) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const bool has_value = i + 1 < argc;
    if (arg == "--runs" && has_value) {
      options.runs = std::strtol(argv[++i], nullptr, 10);
    } else if (arg == "--seed" && has_value) {
      options.seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (arg == "--last-input" && has_value) {
      options.last_input = argv[++i];
    } else if (arg == "--max-len" && has_value) {
      options.max_len = std::strtoull(argv[++i], nullptr, 10);
    } else if (arg == "-h" || arg == "--help") {
      std::printf(
          "usage: %s [--runs N] [--seed S] [--max-len BYTES] [--last-input FILE] SEED_FILE_OR_DIR...\n",
          argv[0]);
      std::exit(0);
    } else if (!arg.empty() && arg[0] == '-') {
      std::fprintf(stderr, "fuzz driver: unknown option '%s' (see --help)\n", arg.c_str());
      return false;
    } else {
      options.inputs.push_back(arg);
    }
  }
  return true;
}

Bytes read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::vector<Bytes> load_seeds(const std::vector<std::string>& inputs) {
  std::vector<std::filesystem::path> files;
  for (const auto& input : inputs) {
    if (std::filesystem::is_directory(input)) {
      for (const auto& entry : std::filesystem::directory_iterator(input))
        if (entry.is_regular_file()) files.push_back(entry.path());
    } else {
      files.emplace_back(input);
    }
  }
  std::sort(files.begin(), files.end());  // a directory's order is not stable
  std::vector<Bytes> seeds;
  for (const auto& file : files) seeds.push_back(read_file(file));
  if (seeds.empty()) seeds.emplace_back();
  return seeds;
}

class Mutator {
 public:
  Mutator(std::uint64_t seed, std::size_t max_len) : rng_(seed), max_len_(max_len) {}

  Bytes mutate(const std::vector<Bytes>& seeds) {
    Bytes data = seeds[pick(seeds.size())];
    const int steps = 1 + static_cast<int>(pick(4));
    for (int s = 0; s < steps; ++s) mutate_once(data, seeds);
    if (data.size() > max_len_) data.resize(max_len_);
    return data;
  }

 private:
  std::size_t pick(std::size_t n) {
    return n == 0 ? 0 : std::uniform_int_distribution<std::size_t>(0, n - 1)(rng_);
  }

  void mutate_once(Bytes& data, const std::vector<Bytes>& seeds) {
    static constexpr std::array<std::uint8_t, 12> kInteresting = {0x00, 0x01, 0x7f, 0x80, 0xff, '"',
                                                                  '{',  '}',  '\n', '\\', ':',  0xc3};
    const std::size_t op = pick(8);
    if (data.empty() && op != 2 && op != 7) {
      data.push_back(kInteresting[pick(kInteresting.size())]);
      return;
    }
    switch (op) {
      case 0:  // flip a bit
        data[pick(data.size())] ^= static_cast<std::uint8_t>(1u << pick(8));
        break;
      case 1:  // an interesting byte
        data[pick(data.size())] = kInteresting[pick(kInteresting.size())];
        break;
      case 2: {  // insert random bytes
        const std::size_t at = pick(data.size() + 1), n = 1 + pick(16);
        Bytes insert(n);
        for (auto& b : insert) b = static_cast<std::uint8_t>(pick(256));
        data.insert(data.begin() + static_cast<std::ptrdiff_t>(at), insert.begin(), insert.end());
        break;
      }
      case 3: {  // delete a range
        const std::size_t at = pick(data.size()), n = 1 + pick(std::min<std::size_t>(data.size() - at, 64));
        data.erase(data.begin() + static_cast<std::ptrdiff_t>(at),
                   data.begin() + static_cast<std::ptrdiff_t>(at + n));
        break;
      }
      case 4: {  // duplicate a range
        const std::size_t at = pick(data.size()), n = 1 + pick(std::min<std::size_t>(data.size() - at, 64));
        const Bytes copy(data.begin() + static_cast<std::ptrdiff_t>(at),
                         data.begin() + static_cast<std::ptrdiff_t>(at + n));
        data.insert(data.begin() + static_cast<std::ptrdiff_t>(pick(data.size() + 1)), copy.begin(),
                    copy.end());
        break;
      }
      case 5:  // truncate
        data.resize(pick(data.size() + 1));
        break;
      case 6: {  // overwrite with a random 32-bit value
        const std::size_t at = pick(data.size());
        for (std::size_t i = at; i < std::min(data.size(), at + 4); ++i)
          data[i] = static_cast<std::uint8_t>(pick(256));
        break;
      }
      default: {  // splice: head of this input, tail of another seed
        const Bytes& other = seeds[pick(seeds.size())];
        const std::size_t cut = pick(data.size() + 1), from = pick(other.size() + 1);
        data.resize(cut);
        data.insert(data.end(), other.begin() + static_cast<std::ptrdiff_t>(from), other.end());
        break;
      }
    }
  }

  std::mt19937_64 rng_;
  std::size_t max_len_;
};

}  // namespace

int main(int argc, char** argv) {
  Options options;
  if (!parse_args(argc, argv, options)) return 2;
  const std::vector<Bytes> seeds = load_seeds(options.inputs);
  const auto run_one = [&](const Bytes& input) {
    if (!options.last_input.empty()) {
      std::ofstream(options.last_input, std::ios::binary | std::ios::trunc)
          .write(reinterpret_cast<const char*>(input.data()), static_cast<std::streamsize>(input.size()));
    }
    LLVMFuzzerTestOneInput(input.data(), input.size());
  };
  for (const auto& seed : seeds) run_one(seed);
  Mutator mutator(options.seed, options.max_len);
  for (long run = 0; run < options.runs; ++run) run_one(mutator.mutate(seeds));
  std::printf("fuzz driver: %zu seeds and %ld mutated inputs ran (seed %llu)\n", seeds.size(), options.runs,
              static_cast<unsigned long long>(options.seed));
  return 0;
}

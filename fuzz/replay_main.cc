// The regression half of fuzzing, in the normal build and CTest (docs/fuzzing.md, "In CI"): a fuzz target's
// LLVMFuzzerTestOneInput on every file of the folders given (its committed seeds, fuzz/corpus/<name>/, and any
// crash input a campaign saved), then on inputs mutated from them with a fixed seed: bit flips, byte changes,
// truncations, insertions, repeated blocks, splices of two seeds, and random bytes. The mutations are blind (no
// coverage guidance) and the build has no sanitizers: this catches a crash, an abort of the target's own checks,
// an uncaught exception or a hang (CTest's timeout) on inputs near the seeds, the same on every machine. Finding
// new inputs is the libFuzzer campaign's job (scripts/fuzz.sh: clang, ASan and UBSan, coverage-guided).
//
//   replay_<target> [--mutations N] [--max-len BYTES] [--seed S] [--dict FILE] [--save M FILE] DIR...
//
// --dict: a libFuzzer dictionary (fuzz/<name>.dict: one "token" a line, \\ \" and \xNN escapes); its tokens are
// inserted and overwritten as one more kind of mutation, which is what gets a JSON or HTTP input past its syntax.
//
// Prints a line per input before running it and a summary; exit 0 when every input returned, 2 on bad arguments.
// An input that crashes the target ends the process with its signal: the last "input" line names it, and the
// same command with --save M FILE writes mutation M to FILE (for the fuzz build: build-fuzz/bin/fuzz_... FILE).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

using Bytes = std::vector<std::uint8_t>;

// A libFuzzer dictionary's tokens; a line that is not a quoted token (a comment, a blank) is skipped.
std::vector<Bytes> ReadDict(const std::filesystem::path& path, std::string* error) {
  std::ifstream in(path);
  if (!in) {
    *error = "--dict: cannot read " + path.string();
    return {};
  }
  std::vector<Bytes> tokens;
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    const auto open = line.find('"');
    const auto close = line.rfind('"');
    if (line.empty() || line[0] == '#' || open == std::string::npos || close <= open) continue;
    Bytes t;
    for (std::size_t k = open + 1; k < close; ++k) {
      if (line[k] != '\\' || k + 1 >= close) {
        t.push_back(static_cast<std::uint8_t>(line[k]));
      } else if (line[k + 1] == 'x') {
        const std::string hex = k + 3 < close ? line.substr(k + 2, 2) : std::string();
        char* end = nullptr;
        const long v = hex.size() == 2 ? std::strtol(hex.c_str(), &end, 16) : -1;
        if (v < 0 || end == nullptr || *end != '\0') {
          *error = "--dict: " + path.string() + " line " + std::to_string(n) + ": \\x needs two hex digits";
          return {};
        }
        t.push_back(static_cast<std::uint8_t>(v));
        k += 3;
      } else {
        t.push_back(static_cast<std::uint8_t>(line[++k]));
      }
    }
    if (!t.empty()) tokens.push_back(std::move(t));
  }
  if (tokens.empty()) *error = "--dict: no token in " + path.string() + " (" + std::to_string(n) + " lines)";
  return tokens;
}

Bytes Mutate(const std::vector<Bytes>& seeds, const std::vector<Bytes>& dict, std::mt19937_64& rng,
             std::size_t max_len) {
  auto pick = [&rng](std::size_t n) { return static_cast<std::size_t>(rng() % std::max<std::size_t>(n, 1)); };
  Bytes b = seeds.empty() ? Bytes{} : seeds[pick(seeds.size())];
  const int edits = 1 + static_cast<int>(pick(8));
  for (int e = 0; e < edits; ++e) {
    switch (pick(dict.empty() ? 8 : 10)) {
      case 0:  // a bit flipped
        if (!b.empty()) b[pick(b.size())] ^= static_cast<std::uint8_t>(1u << pick(8));
        break;
      case 1:  // a byte replaced, often by an edge value
        if (!b.empty()) {
          static const std::uint8_t kEdge[] = {0, 1, 0x7f, 0x80, 0xff, '0', '9', '-', '.', ',', '\n', '"', 'e'};
          b[pick(b.size())] = pick(2) ? kEdge[pick(sizeof kEdge)] : static_cast<std::uint8_t>(rng());
        }
        break;
      case 2:  // truncated
        b.resize(pick(b.size() + 1));
        break;
      case 3: {  // bytes inserted
        const std::size_t at = pick(b.size() + 1), n = 1 + pick(16);
        Bytes ins(n);
        for (auto& x : ins) x = static_cast<std::uint8_t>(rng());
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), ins.begin(), ins.end());
        break;
      }
      case 4:  // a block erased
        if (!b.empty()) {
          const std::size_t at = pick(b.size()), n = 1 + pick(std::min<std::size_t>(b.size() - at, 64));
          b.erase(b.begin() + static_cast<std::ptrdiff_t>(at), b.begin() + static_cast<std::ptrdiff_t>(at + n));
        }
        break;
      case 5:  // a block repeated
        if (!b.empty()) {
          const std::size_t at = pick(b.size()), n = 1 + pick(std::min<std::size_t>(b.size() - at, 64));
          const Bytes block(b.begin() + static_cast<std::ptrdiff_t>(at),
                            b.begin() + static_cast<std::ptrdiff_t>(at + n));
          b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), block.begin(), block.end());
        }
        break;
      case 6:  // spliced with another seed
        if (!seeds.empty()) {
          const Bytes& o = seeds[pick(seeds.size())];
          b.resize(pick(b.size() + 1));
          b.insert(b.end(), o.begin() + static_cast<std::ptrdiff_t>(pick(o.size() + 1)), o.end());
        }
        break;
      case 7: {  // random bytes
        b.resize(pick(std::min<std::size_t>(max_len, 512) + 1));
        for (auto& x : b) x = static_cast<std::uint8_t>(rng());
        break;
      }
      case 8: {  // a dictionary token inserted
        const Bytes& t = dict[pick(dict.size())];
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(pick(b.size() + 1)), t.begin(), t.end());
        break;
      }
      default: {  // a dictionary token written over the input
        const Bytes& t = dict[pick(dict.size())];
        const std::size_t at = pick(b.size() + 1);
        if (b.size() < at + t.size()) b.resize(at + t.size());
        std::copy(t.begin(), t.end(), b.begin() + static_cast<std::ptrdiff_t>(at));
        break;
      }
    }
  }
  if (b.size() > max_len) b.resize(max_len);
  return b;
}

int Usage(const char* why) {
  std::fprintf(stderr,
               "replay: %s\nusage: replay [--mutations N] [--max-len BYTES] [--seed S] [--dict FILE] "
               "[--save M FILE] DIR...\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  long mutations = 200, max_len = 4096, save = -1;
  std::string save_path;
  std::vector<Bytes> dict;
  unsigned long long seed = 1;
  std::vector<std::filesystem::path> dirs;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    auto number = [&](long* out) {
      if (k + 1 >= argc) return false;
      char* end = nullptr;
      *out = std::strtol(argv[++k], &end, 10);
      return end != nullptr && *end == '\0' && *out >= 0;
    };
    if (a == "--mutations") {
      if (!number(&mutations)) return Usage("--mutations: a count >= 0");
    } else if (a == "--max-len") {
      if (!number(&max_len) || max_len < 1) return Usage("--max-len: a byte count >= 1");
    } else if (a == "--seed") {
      long s = 0;
      if (!number(&s)) return Usage("--seed: an integer >= 0");
      seed = static_cast<unsigned long long>(s);
    } else if (a == "--dict") {
      if (k + 1 >= argc) return Usage("--dict: a file");
      std::string error;
      dict = ReadDict(argv[++k], &error);
      if (!error.empty()) return Usage(error.c_str());
    } else if (a == "--save") {
      if (!number(&save) || k + 1 >= argc) return Usage("--save: a mutation number and a file");
      save_path = argv[++k];
    } else if (!a.empty() && a[0] == '-') {
      return Usage(("unknown option " + a).c_str());
    } else {
      dirs.emplace_back(a);
    }
  }
  if (dirs.empty()) return Usage("no seed folder");
  std::vector<std::filesystem::path> files;
  for (const auto& d : dirs) {
    std::error_code ec;
    if (!std::filesystem::is_directory(d, ec)) return Usage(("not a folder: " + d.string()).c_str());
    for (const auto& e : std::filesystem::directory_iterator(d, ec))
      if (e.is_regular_file()) files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());  // the same order, so the same mutations, on every machine
  std::vector<Bytes> seeds;
  for (const auto& f : files) {
    std::ifstream in(f, std::ios::binary);
    seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (save >= 0) continue;
    std::printf("input %s (%zu bytes)\n", f.string().c_str(), seeds.back().size());
    std::fflush(stdout);
    LLVMFuzzerTestOneInput(seeds.back().data(), seeds.back().size());
  }
  std::mt19937_64 rng(seed);
  for (long m = 0; m < mutations; ++m) {
    const Bytes b = Mutate(seeds, dict, rng, static_cast<std::size_t>(max_len));
    if (m + 1 == save) {
      std::ofstream(save_path, std::ios::binary).write(reinterpret_cast<const char*>(b.data()),
                                                        static_cast<std::streamsize>(b.size()));
      std::printf("mutation %ld (%zu bytes) written to %s\n", save, b.size(), save_path.c_str());
      return 0;
    }
    if (save < 0) {
      std::printf("input mutation %ld of %ld (%zu bytes)\n", m + 1, mutations, b.size());
      std::fflush(stdout);
      LLVMFuzzerTestOneInput(b.data(), b.size());
    }
  }
  if (save >= 0) return Usage("--save: no such mutation (beyond --mutations)");
  std::printf("%zu seed inputs and %ld mutated inputs (seed %llu, %zu dictionary tokens) returned\n", seeds.size(),
              mutations, seed, dict.size());
  return 0;
}

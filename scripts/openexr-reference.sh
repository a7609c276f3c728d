#!/usr/bin/env bash
# Optional: times symframe's EXR decoder against the OpenEXR C++ library on the same files, one
# thread each, files read into memory first (docs/performance.md, "Decoding").
#
#   scripts/openexr-reference.sh [ROUNDS] FILE.exr...
#
# Needs g++, pkg-config and OpenEXR's development files (Debian: apt-get install
# libopenexr-dev); nothing of it is a build dependency of symframe. Builds a small C++ timing
# program in a temporary folder, builds the `decode_time` example of symframe-io, then runs
# the two alternately ROUNDS times (default 3) and prints each one's best and median time per
# image and its throughput.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=3
if [[ "${1:-}" =~ ^[0-9]+$ ]]; then
    rounds=$1
    shift
fi
[ $# -gt 0 ] || { sed -n '2,11p' "$0"; exit 2; }
command -v g++ >/dev/null && pkg-config --exists OpenEXR || {
    echo "needs g++ and OpenEXR's development files (apt-get install libopenexr-dev)" >&2
    exit 1
}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat >"$tmp/exr_time.cpp" <<'CPP'
// Times OpenEXR decoding of float RGB files into an interleaved f32 buffer, one thread, files in memory.
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfThreading.h>
#include <Imath/ImathBox.h>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

class MemStream : public Imf::IStream {
  const std::vector<char>& b; uint64_t pos = 0;
public:
  MemStream(const std::vector<char>& b) : Imf::IStream("mem"), b(b) {}
  bool isMemoryMapped() const override { return true; }
  char* readMemoryMapped(int n) override {
    if (pos + n > b.size()) throw std::runtime_error("eof");
    char* p = const_cast<char*>(b.data()) + pos; pos += n; return p;
  }
  bool read(char c[], int n) override {
    if (pos + n > b.size()) throw std::runtime_error("eof");
    memcpy(c, b.data() + pos, n); pos += n; return pos < b.size();
  }
  uint64_t tellg() override { return pos; }
  void seekg(uint64_t p) override { pos = p; }
};

int main(int argc, char** argv) {
  int repeats = 5, first = 1;
  if (argc > 2 && std::string(argv[1]) == "-r") { repeats = atoi(argv[2]); first = 3; }
  Imf::setGlobalThreadCount(0);
  std::vector<std::vector<char>> files;
  size_t file_bytes = 0;
  for (int i = first; i < argc; i++) {
    std::ifstream f(argv[i], std::ios::binary);
    files.emplace_back(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    file_bytes += files.back().size();
  }
  std::vector<double> times; size_t samples = 0; double sink = 0;
  for (int r = 0; r < repeats; r++) {
    auto t0 = std::chrono::steady_clock::now();
    samples = 0;
    for (auto& b : files) {
      MemStream s(b);
      Imf::InputFile in(s);
      Imath::Box2i dw = in.header().dataWindow();
      int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
      std::vector<float> px((size_t)w * h * 3);
      Imf::FrameBuffer fb;
      char* base = (char*)(px.data() - 3 * ((size_t)dw.min.x + (size_t)dw.min.y * w));
      const char* names[3] = {"R", "G", "B"};
      for (int c = 0; c < 3; c++)
        fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + 4 * c, 12, 12 * (size_t)w));
      in.setFrameBuffer(fb);
      in.readPixels(dw.min.y, dw.max.y);
      samples += px.size(); sink += px[px.size() / 2];
    }
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(times.begin(), times.end());
  double best = times[0], med = times[times.size() / 2], n = files.size();
  printf("OpenEXR %s: %zu files; per image: best %.3f ms, median %.3f ms; %.0f MB/s of samples, %.0f MB/s of file (best)%s\n",
         OPENEXR_VERSION_STRING, files.size(), best / n * 1e3, med / n * 1e3, samples * 4 / best / 1e6, file_bytes / best / 1e6, sink == 12345.678 ? "!" : "");
}
CPP
g++ -O2 -std=c++17 "$tmp/exr_time.cpp" -o "$tmp/exr_time" $(pkg-config --cflags --libs OpenEXR)
cargo build --release -q -p symframe-io --example decode_time
for _ in $(seq "$rounds"); do
    echo -n "symframe: " && target/release/examples/decode_time -r 3 "$@"
    "$tmp/exr_time" -r 3 "$@"
done

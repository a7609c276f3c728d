// The OpenEXR C++ library's side of scripts/exr-compression-bench.sh (docs/performance.md,
// "Decoding, every compression"): writes test files with OpenEXR itself, times OpenEXR's decoding
// of R, G, B into one interleaved float buffer on one thread, and checksums what it decodes so
// that symframe's result can be compared to the bit.
//
//   exr-reference write DIR SIZE COUNT [TILE]
//                                        COUNT images of SIZE x SIZE, float RGB content, written
//                                        as DIR/{scan,tile}-{half,float}-COMPRESSION/NNNN.exr for
//                                        every compression OpenEXR writes (tiles of TILE x TILE,
//                                        default 64)
//   exr-reference time [-r R] FILES...   best and median decode time per image over R rounds
//   exr-reference sum FILES...           FNV-1a 64 of the decoded floats of every file in order
//
// Built by the bench script with g++ and `pkg-config OpenEXR` (Debian: libopenexr-dev).
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfTiledInputFile.h>
#include <OpenEXR/ImfTiledOutputFile.h>
#include <OpenEXR/ImfVersion.h>
#include <Imath/ImathBox.h>
#include <Imath/half.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <sys/stat.h>
#include <vector>

// The file held in memory, so that the disk is not timed.
class MemStream : public Imf::IStream {
  const std::vector<char>& b;
  uint64_t pos = 0;

 public:
  explicit MemStream(const std::vector<char>& b) : Imf::IStream("mem"), b(b) {}
  bool isMemoryMapped() const override { return true; }
  char* readMemoryMapped(int n) override {
    if (pos + n > b.size()) throw std::runtime_error("eof");
    char* p = const_cast<char*>(b.data()) + pos;
    pos += n;
    return p;
  }
  bool read(char c[], int n) override {
    if (pos + n > b.size()) throw std::runtime_error("eof");
    memcpy(c, b.data() + pos, n);
    pos += n;
    return pos < b.size();
  }
  uint64_t tellg() override { return pos; }
  void seekg(uint64_t p) override { pos = p; }
};

// Decodes R, G, B of `b` into `px` (interleaved floats), through the tiled reader for a tiled
// file (OpenEXR's fastest path for tiles) and the scan-line reader otherwise.
static void decode(const std::vector<char>& b, std::vector<float>& px) {
  MemStream s(b);
  Imf::InputFile probe(s);
  const Imf::Header& h = probe.header();
  Imath::Box2i dw = h.dataWindow();
  size_t w = dw.max.x - dw.min.x + 1, hh = dw.max.y - dw.min.y + 1;
  px.assign(w * hh * 3, 0.0f);
  Imf::FrameBuffer fb;
  char* base = (char*)(px.data() - 3 * ((size_t)dw.min.x + (size_t)dw.min.y * w));
  const char* names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; c++)
    fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + 4 * c, 12, 12 * w));
  if (h.hasTileDescription()) {
    MemStream t(b);
    Imf::TiledInputFile in(t);
    in.setFrameBuffer(fb);
    in.readTiles(0, in.numXTiles(0) - 1, 0, in.numYTiles(0) - 1);
  } else {
    probe.setFrameBuffer(fb);
    probe.readPixels(dw.min.y, dw.max.y);
  }
}

static std::vector<std::vector<char>> load(int argc, char** argv, int first) {
  std::vector<std::vector<char>> files;
  for (int i = first; i < argc; i++) {
    std::ifstream f(argv[i], std::ios::binary);
    if (!f) throw std::runtime_error(std::string("cannot read ") + argv[i]);
    files.emplace_back(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  return files;
}

// Image `i` of `n` x `n`: a glossy sphere lit from a direction that turns with `i`, over a
// ground gradient, with 2% multiplicative noise as a path tracer leaves it (HDR: the highlight
// reaches about 20).
static std::vector<float> content(int n, int i) {
  std::vector<float> px((size_t)n * n * 3);
  double a = 0.37 * i, lx = 0.6 * cos(a), ly = 0.6 * sin(a), lz = sqrt(1 - 0.36);
  uint64_t s = 0x9E3779B97F4A7C15ull * (i + 1);
  auto rnd = [&]() {  // xorshift64*, uniform in [0, 1)
    s ^= s >> 12; s ^= s << 25; s ^= s >> 27;
    return ((s * 2685821657736338717ull) >> 11) * (1.0 / 9007199254740992.0);
  };
  for (int y = 0; y < n; y++)
    for (int x = 0; x < n; x++) {
      double u = (x + 0.5) / n * 2 - 1, v = 1 - (y + 0.5) / n * 2, r2 = u * u + v * v;
      double col[3];
      if (r2 < 0.8) {
        double nz = sqrt(0.8 - r2) / sqrt(0.8), nx = u / sqrt(0.8), ny = v / sqrt(0.8);
        double d = std::max(0.0, nx * lx + ny * ly + nz * lz);
        double hx = lx, hy = ly, hz = lz + 1, hn = sqrt(hx * hx + hy * hy + hz * hz);
        double sp = pow(std::max(0.0, (nx * hx + ny * hy + nz * hz) / hn), 60) * 20;
        col[0] = 0.8 * d + sp; col[1] = 0.45 * d + sp; col[2] = 0.2 * d + sp;
      } else {
        double g = 0.05 + 0.1 * (1 - (y + 0.5) / n);
        col[0] = g; col[1] = g * 1.1; col[2] = g * 1.3;
      }
      for (int c = 0; c < 3; c++)
        px[3 * ((size_t)y * n + x) + c] = (float)(col[c] * (1 + 0.04 * (rnd() - 0.5)));
    }
  return px;
}

static int write(const char* dir, int n, int count, int tile) {
  struct { const char* name; Imf::Compression c; } comps[] = {
      {"none", Imf::NO_COMPRESSION},  {"rle", Imf::RLE_COMPRESSION},
      {"zips", Imf::ZIPS_COMPRESSION}, {"zip", Imf::ZIP_COMPRESSION},
      {"piz", Imf::PIZ_COMPRESSION},   {"pxr24", Imf::PXR24_COMPRESSION},
      {"b44", Imf::B44_COMPRESSION},   {"b44a", Imf::B44A_COMPRESSION},
      {"dwaa", Imf::DWAA_COMPRESSION}, {"dwab", Imf::DWAB_COMPRESSION}};
  mkdir(dir, 0755);
  for (int i = 0; i < count; i++) {
    std::vector<float> px = content(n, i);
    for (auto& comp : comps)
      for (int tiled = 0; tiled < 2; tiled++)
        for (int hf = 0; hf < 2; hf++) {
          std::string sub = std::string(dir) + "/" + (tiled ? "tile-" : "scan-") +
                            (hf ? "half-" : "float-") + comp.name;
          mkdir(sub.c_str(), 0755);
          char name[32];
          snprintf(name, sizeof name, "/%04d.exr", i);
          std::string path = sub + name;
          Imf::Header h(n, n);
          h.compression() = comp.c;
          for (const char* c : {"R", "G", "B"})
            h.channels().insert(c, Imf::Channel(hf ? Imf::HALF : Imf::FLOAT));
          // OpenEXR writes a channel only from a slice of its own type.
          std::vector<half> hpx(hf ? px.size() : 0);
          for (size_t k = 0; k < hpx.size(); k++) hpx[k] = half(px[k]);
          Imf::FrameBuffer fb;
          const char* names[3] = {"R", "G", "B"};
          for (int c = 0; c < 3; c++)
            fb.insert(names[c], hf ? Imf::Slice(Imf::HALF, (char*)(hpx.data() + c), 6, 6 * (size_t)n)
                                     : Imf::Slice(Imf::FLOAT, (char*)(px.data() + c), 12, 12 * (size_t)n));
          if (tiled) {
            h.setTileDescription(Imf::TileDescription(tile, tile, Imf::ONE_LEVEL));
            Imf::TiledOutputFile out(path.c_str(), h);
            out.setFrameBuffer(fb);
            out.writeTiles(0, out.numXTiles() - 1, 0, out.numYTiles() - 1);
          } else {
            Imf::OutputFile out(path.c_str(), h);
            out.setFrameBuffer(fb);
            out.writePixels(n);
          }
        }
  }
  return 0;
}

int main(int argc, char** argv) {
  Imf::setGlobalThreadCount(0);
  std::string cmd = argc > 1 ? argv[1] : "";
  if (cmd == "write" && (argc == 5 || argc == 6))
    return write(argv[2], atoi(argv[3]), atoi(argv[4]), argc == 6 ? atoi(argv[5]) : 64);
  if (cmd == "sum" && argc > 2) {
    uint64_t hsh = 0xcbf29ce484222325ull;
    std::vector<float> px;
    for (auto& b : load(argc, argv, 2)) {
      decode(b, px);
      const unsigned char* p = (const unsigned char*)px.data();
      for (size_t i = 0; i < px.size() * 4; i++) hsh = (hsh ^ p[i]) * 0x100000001b3ull;
    }
    printf("%016llx\n", (unsigned long long)hsh);
    return 0;
  }
  if (cmd == "time" && argc > 2) {
    int repeats = 5, first = 2;
    if (argc > 4 && std::string(argv[2]) == "-r") { repeats = atoi(argv[3]); first = 4; }
    auto files = load(argc, argv, first);
    std::vector<double> times;
    std::vector<float> px;
    double sink = 0;
    for (int r = 0; r < repeats; r++) {
      auto t0 = std::chrono::steady_clock::now();
      for (auto& b : files) {
        decode(b, px);
        sink += px[px.size() / 2];
      }
      times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(times.begin(), times.end());
    double n = files.size();
    printf("OpenEXR %s: %zu files; per image: best %.3f ms, median %.3f ms%s\n",
           OPENEXR_VERSION_STRING, files.size(), times[0] / n * 1e3,
           times[times.size() / 2] / n * 1e3, sink == 12345.678 ? "!" : "");
    return 0;
  }
  fprintf(stderr, "usage: exr-reference write DIR SIZE COUNT [TILE] | time [-r R] FILES... | sum FILES...\n");
  return 2;
}

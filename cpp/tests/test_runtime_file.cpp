// The controller file loader (runtime_file.hpp) on hand-built files: every truncation and
// every single-byte change is refused with ControllerFileError or leaves the values unchanged,
// never a crash (CI runs this under AddressSanitizer and UBSan: MMRL_SANITIZE).
#include <gtest/gtest.h>

#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "mmrl/runtime.hpp"
#include "mmrl/runtime_file.hpp"

namespace mmrl {
namespace {

struct TestSection {
  std::string name;
  uint32_t type;
  std::vector<uint64_t> shape;
  std::vector<uint8_t> data;
};

template <class T>
void put(std::vector<uint8_t>& out, size_t at, T value) {
  std::memcpy(out.data() + at, &value, sizeof(T));
}

// Writes the format of docs/runtime.md (the reference writer is python/mmrl/export/runtime_file.py).
std::vector<uint8_t> build_file(const std::vector<TestSection>& sections) {
  const size_t table_end = 64 + 128 * sections.size();
  size_t offset = (table_end + 63) / 64 * 64;
  std::vector<uint8_t> out(offset, 0);
  for (size_t k = 0; k < sections.size(); ++k) {
    const TestSection& s = sections[k];
    const size_t e = 64 + 128 * k;
    std::memcpy(out.data() + e, s.name.data(), s.name.size());
    put<uint32_t>(out, e + 64, s.type);
    put<uint32_t>(out, e + 68, static_cast<uint32_t>(s.shape.size()));
    for (size_t a = 0; a < s.shape.size(); ++a) put<uint64_t>(out, e + 72 + 8 * a, s.shape[a]);
    put<uint64_t>(out, e + 104, offset);
    put<uint64_t>(out, e + 112, s.data.size());
    put<uint32_t>(out, e + 120, crc32(s.data.data(), s.data.size()));
    out.insert(out.end(), s.data.begin(), s.data.end());
    out.resize((out.size() + 63) / 64 * 64, 0);
    offset = out.size();
  }
  std::memcpy(out.data(), kControllerMagic, 8);
  put<uint32_t>(out, 8, kControllerVersion);
  put<uint32_t>(out, 12, kControllerEndianMarker);
  put<uint32_t>(out, 16, 64);
  put<uint32_t>(out, 20, static_cast<uint32_t>(sections.size()));
  put<uint64_t>(out, 24, 64);
  put<uint64_t>(out, 32, out.size());
  put<uint32_t>(out, 40, crc32(out.data() + 64, 128 * sections.size()));
  put<uint32_t>(out, 44, crc32(out.data(), 44));
  return out;
}

std::vector<uint8_t> bytes_of(const void* p, size_t n) {
  const uint8_t* b = static_cast<const uint8_t*>(p);
  return std::vector<uint8_t>(b, b + n);
}

std::vector<TestSection> sample_sections() {
  const float f[6] = {1, 2, 3, 4, 5, 6};
  const int32_t i[3] = {-1, 0, 1};
  const double d[2] = {0.5, 60.0};
  const char text[] = "Hips\0LeftUpLeg\0";
  return {{"a.floats", 1, {2, 3}, bytes_of(f, sizeof f)},
          {"a.ints", 2, {3}, bytes_of(i, sizeof i)},
          {"a.text", 4, {2}, bytes_of(text, sizeof text - 1)},
          {"a.doubles", 5, {2}, bytes_of(d, sizeof d)},
          {"a.empty", 3, {0}, {}}};
}

TEST(RuntimeFile, Crc32IsZlibs) {
  const char* check = "123456789";
  EXPECT_EQ(crc32(reinterpret_cast<const uint8_t*>(check), 9), 0xCBF43926u);
  std::vector<uint8_t> long_input(1000);
  for (size_t k = 0; k < long_input.size(); ++k) long_input[k] = static_cast<uint8_t>(k * 7);
  // The 8-byte path and the byte path agree: the CRC of a split input continues the first part's.
  EXPECT_EQ(crc32(long_input.data() + 3, 997, crc32(long_input.data(), 3)), crc32(long_input.data(), 1000));
}

TEST(RuntimeFile, ReadsTypedSections) {
  const ControllerFile f = ControllerFile::parse(build_file(sample_sections()), "mem.mmrl");
  EXPECT_EQ(f.floats("a.floats", {2, 3}), (std::vector<float>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(f.ints("a.ints", {-1}), (std::vector<int32_t>{-1, 0, 1}));
  EXPECT_EQ(f.texts("a.text"), (std::vector<std::string>{"Hips", "LeftUpLeg"}));
  EXPECT_EQ(f.doubles("a.doubles"), (std::vector<double>{0.5, 60.0}));
  EXPECT_TRUE(f.bytes("a.empty", {0}).empty());
}

void expect_error(const std::function<void()>& call, const std::string& part) {
  try {
    call();
    ADD_FAILURE() << "no error; expected one containing: " << part;
  } catch (const ControllerFileError& e) {
    EXPECT_NE(std::string(e.what()).find("mem.mmrl: "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(RuntimeFile, WrongTypeShapeOrNameNamesTheSection) {
  const ControllerFile f = ControllerFile::parse(build_file(sample_sections()), "mem.mmrl");
  expect_error([&] { f.ints("a.floats"); }, "section 'a.floats' is float32, expected int32");
  expect_error([&] { f.floats("a.floats", {3, 2}); }, "section 'a.floats' has shape (2, 3), expected (3, 2)");
  expect_error([&] { f.floats("a.nothing"); }, "missing section 'a.nothing'");
  expect_error([&] { RuntimeController::from_file(ControllerFile::parse(build_file(sample_sections()), "mem.mmrl")); },
               "missing section 'db.");
}

TEST(RuntimeFile, HeaderErrorsSayWhatIsWrong) {
  auto file = build_file(sample_sections());
  auto with = [&](size_t at, uint32_t value) {
    auto copy = file;
    put<uint32_t>(copy, at, value);
    return copy;
  };
  expect_error([&] { ControllerFile::parse(with(8, 7), "mem.mmrl"); }, "version 7, this runtime reads version 1");
  expect_error([&] { ControllerFile::parse(with(12, 0x0D0C0B0Au), "mem.mmrl"); }, "big-endian");
  expect_error([&] { ControllerFile::parse(with(0, 0x04034B50u), "mem.mmrl"); }, "not an mmrl controller file");
  expect_error([&] { ControllerFile::parse(std::vector<uint8_t>(file.begin(), file.end() - 1), "mem.mmrl"); },
               "truncated");
}

// Every value the sample file holds, as one comparable string.
std::string contents(const ControllerFile& f) {
  std::string s;
  for (float v : f.floats("a.floats", {2, 3})) s += std::to_string(v) + ",";
  for (int32_t v : f.ints("a.ints", {3})) s += std::to_string(v) + ",";
  for (const auto& t : f.texts("a.text")) s += t + ",";
  for (double v : f.doubles("a.doubles", {2})) s += std::to_string(v) + ",";
  s += std::to_string(f.bytes("a.empty", {0}).size());
  return s;
}

TEST(RuntimeFile, EveryTruncationIsRefused) {
  const auto file = build_file(sample_sections());
  for (size_t n = 0; n < file.size(); ++n)
    EXPECT_THROW(ControllerFile::parse(std::vector<uint8_t>(file.begin(), file.begin() + n), "mem.mmrl"),
                 ControllerFileError)
        << n;
}

TEST(RuntimeFile, EveryByteChangeIsRefusedOrHarmless) {
  const auto file = build_file(sample_sections());
  const std::string expected = contents(ControllerFile::parse(file, "mem.mmrl"));
  int refused = 0;
  for (size_t at = 0; at < file.size(); ++at)
    for (uint8_t mask : {0x01, 0x80, 0xFF}) {
      auto copy = file;
      copy[at] ^= mask;
      try {
        // Accepted only where the byte is padding no section covers: the values are unchanged.
        EXPECT_EQ(contents(ControllerFile::parse(copy, "mem.mmrl")), expected) << at;
      } catch (const ControllerFileError&) {
        ++refused;
      }
    }
  EXPECT_GT(refused, static_cast<int>(file.size()));  // most changes hit a checked byte
}

}  // namespace
}  // namespace mmrl

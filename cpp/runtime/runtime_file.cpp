#include "mmrl/runtime_file.hpp"

#include <array>
#include <cstdio>
#include <cstring>
#include <memory>

namespace mmrl {

namespace {

// Slicing-by-8 tables: 8 bytes per step, about 1.5 GB/s (a 150k-frame file in ~70 ms).
struct CrcTables {
  std::array<std::array<uint32_t, 256>, 8> t{};
  CrcTables() {
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; ++i)
      for (int s = 1; s < 8; ++s) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFF];
  }
};

template <class T>
T load_le(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));  // the host is little-endian (checked in parse)
  return v;
}

bool host_is_little_endian() {
  const uint32_t one = 1;
  uint8_t b;
  std::memcpy(&b, &one, 1);
  return b == 1;
}

size_t type_size(SectionType t) {
  switch (t) {
    case SectionType::kFloat32:
    case SectionType::kInt32: return 4;
    case SectionType::kFloat16: return 2;
    case SectionType::kFloat64: return 8;
    default: return 1;
  }
}

const char* type_name(SectionType t) {
  switch (t) {
    case SectionType::kFloat32: return "float32";
    case SectionType::kInt32: return "int32";
    case SectionType::kUInt8: return "uint8";
    case SectionType::kText: return "text";
    case SectionType::kFloat64: return "float64";
    case SectionType::kFloat16: return "float16";
  }
  return "?";
}

std::string shape_text(const std::vector<int64_t>& shape) {
  std::string s = "(";
  for (size_t k = 0; k < shape.size(); ++k) s += (k ? ", " : "") + std::to_string(shape[k]);
  return s + (shape.size() == 1 ? ",)" : ")");
}

}  // namespace

uint32_t crc32(const uint8_t* p, size_t n, uint32_t crc) {
  static const CrcTables tables;
  const auto& t = tables.t;
  crc = ~crc;
  while (n >= 8) {
    const uint32_t a = crc ^ load_le<uint32_t>(p), b = load_le<uint32_t>(p + 4);
    crc = t[7][a & 0xFF] ^ t[6][(a >> 8) & 0xFF] ^ t[5][(a >> 16) & 0xFF] ^ t[4][a >> 24] ^ t[3][b & 0xFF] ^
          t[2][(b >> 8) & 0xFF] ^ t[1][(b >> 16) & 0xFF] ^ t[0][b >> 24];
    p += 8;
    n -= 8;
  }
  while (n--) crc = t[0][(crc ^ *p++) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

void ControllerFile::fail(const std::string& what) const { throw ControllerFileError(path_ + ": " + what); }

ControllerFile ControllerFile::read(const std::string& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) throw ControllerFileError(path + ": cannot open the controller file");
  std::vector<uint8_t> bytes;
  if (std::fseek(f.get(), 0, SEEK_END) != 0) throw ControllerFileError(path + ": cannot seek (not a regular file?)");
  const long size = std::ftell(f.get());
  if (size < 0) throw ControllerFileError(path + ": cannot tell the file's size");
  std::rewind(f.get());
  bytes.resize(static_cast<size_t>(size));
  if (size > 0 && std::fread(bytes.data(), 1, bytes.size(), f.get()) != bytes.size())
    throw ControllerFileError(path + ": read error");
  return parse(std::move(bytes), path);
}

// long: one pass over the header and the table, each check with its own message.
ControllerFile ControllerFile::parse(std::vector<uint8_t> bytes, const std::string& path) {
  ControllerFile cf;
  cf.path_ = path;
  cf.bytes_ = std::move(bytes);
  const uint8_t* d = cf.bytes_.data();
  const uint64_t n = cf.bytes_.size();
  if (!host_is_little_endian()) cf.fail("this runtime reads controller files on little-endian machines only");
  if (n < kControllerHeaderSize)
    cf.fail("truncated: " + std::to_string(n) + " bytes, shorter than the 64-byte header");
  if (std::memcmp(d, kControllerMagic, 8) != 0) cf.fail("not an mmrl controller file (bad magic bytes)");
  const uint32_t endian = load_le<uint32_t>(d + 12);
  if (endian == 0x0D0C0B0Au) cf.fail("big-endian (byte-swapped) file; controller files are little-endian");
  if (endian != kControllerEndianMarker) cf.fail("bad endianness marker");
  const uint32_t version = load_le<uint32_t>(d + 8);
  if (version != kControllerVersion)
    throw ControllerVersionError(cf.path() + ": controller file version " + std::to_string(version) +
                                 ", this runtime reads version " + std::to_string(kControllerVersion) +
                                 "; export it again with 'mmrl export'");
  if (crc32(d, 44) != load_le<uint32_t>(d + 44)) cf.fail("corrupt header (checksum mismatch)");
  for (uint32_t k = 48; k < kControllerHeaderSize; ++k)
    if (d[k] != 0) cf.fail("corrupt header (reserved bytes are not zero)");
  const uint32_t header_size = load_le<uint32_t>(d + 16), count = load_le<uint32_t>(d + 20);
  const uint64_t table_offset = load_le<uint64_t>(d + 24), file_size = load_le<uint64_t>(d + 32);
  if (header_size != kControllerHeaderSize || table_offset != kControllerHeaderSize) cf.fail("corrupt header (sizes)");
  if (file_size != n)
    cf.fail("truncated or padded: the header says " + std::to_string(file_size) + " bytes, the file has " +
            std::to_string(n));
  if (count > (n - kControllerHeaderSize) / kControllerEntrySize)
    cf.fail("truncated: the section table (" + std::to_string(count) + " entries) runs past the end of the file");
  const uint8_t* table = d + kControllerHeaderSize;
  if (crc32(table, static_cast<size_t>(count) * kControllerEntrySize) != load_le<uint32_t>(d + 40))
    cf.fail("corrupt section table (checksum mismatch)");
  for (uint32_t k = 0; k < count; ++k) {
    const uint8_t* e = table + static_cast<size_t>(k) * kControllerEntrySize;
    const char* raw = reinterpret_cast<const char*>(e);
    const std::string name(raw, strnlen(raw, kControllerNameSize - 1));
    const std::string where = "section '" + name + "': ";
    FileSection s;
    const uint32_t type = load_le<uint32_t>(e + 64), ndim = load_le<uint32_t>(e + 68);
    if (type < 1 || type > 6 || ndim > 4) cf.fail(where + "unknown dtype code or more than 4 dimensions");
    s.type = static_cast<SectionType>(type);
    uint64_t count_values = 1;
    for (uint32_t a = 0; a < ndim; ++a) {
      const uint64_t dim = load_le<uint64_t>(e + 72 + 8 * a);
      if (dim > n) cf.fail(where + "impossible shape");
      s.shape.push_back(static_cast<int64_t>(dim));
      count_values *= dim;
      if (count_values > n) cf.fail(where + "impossible shape");
    }
    s.offset = load_le<uint64_t>(e + 104);
    s.size = load_le<uint64_t>(e + 112);
    if (s.offset % kControllerAlignment != 0 || s.offset > n || s.size > n - s.offset)
      cf.fail(where + "its bytes lie outside the file or are misaligned (truncated?)");
    if (crc32(d + s.offset, s.size) != load_le<uint32_t>(e + 120)) cf.fail(where + "corrupt (checksum mismatch)");
    if (s.type != SectionType::kText && count_values * type_size(s.type) != s.size)
      cf.fail(where + std::to_string(s.size) + " bytes do not hold shape " + shape_text(s.shape));
    if (!cf.sections_.emplace(name, s).second) cf.fail(where + "appears twice");
  }
  return cf;
}

const FileSection& ControllerFile::section(const std::string& name) const {
  const auto it = sections_.find(name);
  if (it == sections_.end()) fail("missing section '" + name + "'");
  return it->second;
}

const FileSection& ControllerFile::typed(const std::string& name, SectionType type,
                                         const std::vector<int64_t>& shape) const {
  const FileSection& s = section(name);
  if (s.type != type)
    fail("section '" + name + "' is " + type_name(s.type) + ", expected " + type_name(type));
  bool ok = shape.empty() || shape.size() == s.shape.size();
  for (size_t a = 0; ok && a < shape.size(); ++a) ok = shape[a] < 0 || shape[a] == s.shape[a];
  if (!ok) fail("section '" + name + "' has shape " + shape_text(s.shape) + ", expected " + shape_text(shape));
  return s;
}

namespace {
template <class T>
std::vector<T> copy_values(const std::vector<uint8_t>& bytes, const FileSection& s) {
  std::vector<T> out(s.size / sizeof(T));
  if (s.size) std::memcpy(out.data(), bytes.data() + s.offset, s.size);
  return out;
}
}  // namespace

std::vector<float> ControllerFile::floats(const std::string& name, const std::vector<int64_t>& shape) const {
  return copy_values<float>(bytes_, typed(name, SectionType::kFloat32, shape));
}
std::vector<int32_t> ControllerFile::ints(const std::string& name, const std::vector<int64_t>& shape) const {
  return copy_values<int32_t>(bytes_, typed(name, SectionType::kInt32, shape));
}
std::vector<uint8_t> ControllerFile::bytes(const std::string& name, const std::vector<int64_t>& shape) const {
  return copy_values<uint8_t>(bytes_, typed(name, SectionType::kUInt8, shape));
}
std::vector<uint16_t> ControllerFile::halves(const std::string& name, const std::vector<int64_t>& shape) const {
  return copy_values<uint16_t>(bytes_, typed(name, SectionType::kFloat16, shape));
}
std::vector<double> ControllerFile::doubles(const std::string& name, const std::vector<int64_t>& shape) const {
  return copy_values<double>(bytes_, typed(name, SectionType::kFloat64, shape));
}

std::vector<std::string> ControllerFile::texts(const std::string& name) const {
  const FileSection& s = typed(name, SectionType::kText, {});
  if (s.shape.size() != 1) fail("section '" + name + "': a text section has one dimension");
  std::vector<std::string> out;
  size_t start = s.offset;
  const size_t stop = s.offset + s.size;
  for (size_t i = s.offset; i < stop; ++i) {
    if (bytes_[i] != 0) continue;
    out.emplace_back(reinterpret_cast<const char*>(bytes_.data() + start), i - start);
    start = i + 1;
  }
  if (start != stop || static_cast<int64_t>(out.size()) != s.shape[0])
    fail("section '" + name + "': expected " + std::to_string(s.shape[0]) + " NUL-ended strings");
  return out;
}

}  // namespace mmrl

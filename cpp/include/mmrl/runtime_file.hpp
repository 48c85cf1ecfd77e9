// The exported controller file (.mmrl) read back: a versioned, little-endian container of
// named, typed, checksummed sections (docs/runtime.md has the layout field by field;
// python/mmrl/export/runtime_file.py writes it).
//
// Reading never trusts the file: the magic, the endianness marker, the version, the header's
// and the table's CRC-32, every section's bounds, alignment, dtype, shape and CRC-32 are
// checked before any value is used, and a bad file throws ControllerFileError naming the file
// and what is wrong (never a crash: the loader is tested under AddressSanitizer).
#pragma once

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace mmrl {

class ControllerFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A well-formed file of another format version (the C interface reports it apart).
class ControllerVersionError : public ControllerFileError {
 public:
  using ControllerFileError::ControllerFileError;
};

constexpr char kControllerMagic[9] = "MMRLCTRL";
constexpr uint32_t kControllerVersion = 1;
constexpr uint32_t kControllerEndianMarker = 0x0A0B0C0Du;
constexpr uint32_t kControllerHeaderSize = 64;
constexpr uint32_t kControllerEntrySize = 128;
constexpr uint32_t kControllerNameSize = 64;
constexpr uint32_t kControllerAlignment = 64;

enum class SectionType : uint32_t { kFloat32 = 1, kInt32 = 2, kUInt8 = 3, kText = 4, kFloat64 = 5, kFloat16 = 6 };

// One section after checking: its type, shape and bytes (a view into ControllerFile::bytes).
struct FileSection {
  SectionType type = SectionType::kUInt8;
  std::vector<int64_t> shape;
  uint64_t offset = 0, size = 0;
};

// CRC-32 (the zlib / PNG polynomial, reflected, init and final xor 0xFFFFFFFF).
uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc = 0);

// A checked controller file in memory. Typed accessors copy a section out after checking its
// type and shape; each error names the file and the section.
class ControllerFile {
 public:
  // Reads and checks `path` (header, table, every section's bounds and checksum).
  static ControllerFile read(const std::string& path);
  // The same checks on bytes already in memory (`path` only names them in errors).
  static ControllerFile parse(std::vector<uint8_t> bytes, const std::string& path);

  const std::string& path() const { return path_; }
  bool has(const std::string& name) const { return sections_.count(name) != 0; }
  const FileSection& section(const std::string& name) const;  // throws if missing

  // The section's values, checked against `type` and `shape` (-1 in `shape`: any size; an
  // empty `shape` skips the shape check).
  std::vector<float> floats(const std::string& name, const std::vector<int64_t>& shape = {}) const;
  std::vector<int32_t> ints(const std::string& name, const std::vector<int64_t>& shape = {}) const;
  std::vector<uint8_t> bytes(const std::string& name, const std::vector<int64_t>& shape = {}) const;
  // IEEE float16 values as their bits (a compressed controller's weights).
  std::vector<uint16_t> halves(const std::string& name, const std::vector<int64_t>& shape = {}) const;
  std::vector<double> doubles(const std::string& name, const std::vector<int64_t>& shape = {}) const;
  std::vector<std::string> texts(const std::string& name) const;

  // "PATH: what" as a ControllerFileError.
  [[noreturn]] void fail(const std::string& what) const;

  size_t file_size() const { return bytes_.size(); }
  // Drops the file's bytes once every section has been copied out.
  void release() { std::vector<uint8_t>().swap(bytes_); }

 private:
  const FileSection& typed(const std::string& name, SectionType type, const std::vector<int64_t>& shape) const;

  std::string path_;
  std::vector<uint8_t> bytes_;
  std::map<std::string, FileSection> sections_;
};

}  // namespace mmrl

// libFuzzer target: an exported controller file (.mmrl) -> ControllerFile::parse ->
// RuntimeController::from_file (database, policy, task, search tree), then a character
// driven for a few decisions.
//
// The file's CRC-32s would stop almost every mutation at the first checksum, so before
// parsing the target writes the right checksums into a copy of the input (each section's,
// then the table's, then the header's) wherever the header and table say where they are. The
// checksum checks themselves are covered by tests/test_runtime_file.py (every single byte flip
// of the header and table is refused).
//
// A bad file must throw ControllerFileError (the loader's only error type), and a loaded
// controller must run; anything else escaping, a crash, a hang or a sanitizer report is a
// finding.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "mmrl/runtime.hpp"
#include "mmrl/runtime_file.hpp"

namespace {

uint32_t get32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}
uint64_t get64(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
}
void put32(uint8_t* p, uint32_t v) { std::memcpy(p, &v, 4); }

// Rewrites the checksums (little-endian host; the loader refuses others first anyway).
void fix_checksums(std::vector<uint8_t>& b) {
  using namespace mmrl;
  const uint64_t n = b.size();
  if (n < kControllerHeaderSize) return;
  const uint32_t count = get32(&b[20]);
  if (count > (n - kControllerHeaderSize) / kControllerEntrySize) return;
  uint8_t* table = &b[kControllerHeaderSize];
  for (uint32_t k = 0; k < count; ++k) {
    uint8_t* e = table + static_cast<size_t>(k) * kControllerEntrySize;
    const uint64_t offset = get64(e + 104), size = get64(e + 112);
    if (offset <= n && size <= n - offset) put32(e + 120, crc32(&b[0] + offset, size));
  }
  put32(&b[40], crc32(table, static_cast<size_t>(count) * kControllerEntrySize));
  put32(&b[44], crc32(&b[0], 44));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<uint8_t> bytes(data, data + size);
  fix_checksums(bytes);
  std::shared_ptr<const mmrl::RuntimeController> controller;
  try {
    controller = mmrl::RuntimeController::from_file(mmrl::ControllerFile::parse(std::move(bytes), "fuzz.mmrl"));
  } catch (const mmrl::ControllerFileError&) {
    return 0;
  }
  // A loaded controller drives a character: 3 decisions toward a target 5 m away (and
  // obstacles around it for an obstacle task).
  mmrl::RuntimeCharacter ch(controller, 0.0f, 0.0f, 0.0f);
  ch.set_target(3.0f, 4.0f);
  if (controller->task().num_obstacles > 0) {
    const float centre[2] = {1.0f, 1.5f}, half[2] = {0.0f, 0.0f}, angle[1] = {0.3f};
    try {
      ch.set_obstacles(1, centre, half, angle);
    } catch (const std::invalid_argument&) {  // a task whose max_side is below 0: documented refusal
    }
  }
  for (int k = 0; k < 3 * controller->task().frames_per_step; ++k) ch.advance_frame();
  return 0;
}

// The C interface (mmrl_runtime.h) over the C++ runtime (runtime.hpp). Each function converts,
// checks and forwards; every exception stops here and becomes a status and a message.
#include "mmrl_runtime.h"

#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "mmrl/runtime.hpp"
#include "mmrl/runtime_file.hpp"

struct mmrl_controller {
  std::shared_ptr<const mmrl::RuntimeController> c;
  mutable std::string error;
};

struct mmrl_character {
  std::shared_ptr<const mmrl::RuntimeController> controller;
  std::unique_ptr<mmrl::RuntimeCharacter> c;
  std::string error;
};

namespace {

thread_local std::string g_error;

mmrl_status fail(std::string* slot, mmrl_status status, const std::string& message) {
  g_error = message;
  if (slot != nullptr) *slot = message;
  return status;
}

// Runs fn, turning every exception into a status and a message (on the handle's slot and the
// thread's).
template <class Fn>
mmrl_status guarded(std::string* slot, Fn&& fn) {
  try {
    return fn();
  } catch (const mmrl::ControllerVersionError& e) {
    return fail(slot, MMRL_ERROR_VERSION, e.what());
  } catch (const mmrl::ControllerFileError& e) {
    return fail(slot, MMRL_ERROR_FILE, e.what());
  } catch (const std::invalid_argument& e) {
    return fail(slot, MMRL_ERROR_INVALID_ARGUMENT, e.what());
  } catch (const std::bad_alloc&) {
    return fail(slot, MMRL_ERROR_INTERNAL, "out of memory");
  } catch (const std::exception& e) {
    return fail(slot, MMRL_ERROR_INTERNAL, e.what());
  } catch (...) {
    return fail(slot, MMRL_ERROR_INTERNAL, "unknown error");
  }
}

mmrl_status null_error(const char* what) {
  return fail(nullptr, MMRL_ERROR_NULL, std::string(what) + " is NULL");
}

mmrl_status load_into(std::shared_ptr<const mmrl::RuntimeController> c, mmrl_controller** out) {
  auto* h = new mmrl_controller{std::move(c), {}};
  *out = h;
  return MMRL_OK;
}

}  // namespace

extern "C" {

int32_t mmrl_api_version(void) { return MMRL_API_VERSION; }
int32_t mmrl_file_version(void) { return static_cast<int32_t>(mmrl::kControllerVersion); }

const char* mmrl_status_name(mmrl_status status) {
  switch (status) {
    case MMRL_OK: return "MMRL_OK";
    case MMRL_ERROR_INVALID_ARGUMENT: return "MMRL_ERROR_INVALID_ARGUMENT";
    case MMRL_ERROR_FILE: return "MMRL_ERROR_FILE";
    case MMRL_ERROR_VERSION: return "MMRL_ERROR_VERSION";
    case MMRL_ERROR_NULL: return "MMRL_ERROR_NULL";
    case MMRL_ERROR_BUFFER_TOO_SMALL: return "MMRL_ERROR_BUFFER_TOO_SMALL";
    case MMRL_ERROR_INTERNAL: return "MMRL_ERROR_INTERNAL";
  }
  return "MMRL_UNKNOWN_STATUS";
}

const char* mmrl_last_error(void) { return g_error.c_str(); }

mmrl_status mmrl_controller_load(const char* path, mmrl_controller** out) {
  if (out == nullptr) return null_error("out");
  *out = nullptr;
  if (path == nullptr) return null_error("path");
  return guarded(nullptr, [&] { return load_into(mmrl::RuntimeController::load(path), out); });
}

mmrl_status mmrl_controller_load_memory(const void* data, size_t size, const char* name, mmrl_controller** out) {
  if (out == nullptr) return null_error("out");
  *out = nullptr;
  if (data == nullptr && size > 0) return null_error("data");
  return guarded(nullptr, [&] {
    const auto* bytes = static_cast<const uint8_t*>(data);
    std::vector<uint8_t> copy(bytes, bytes + size);
    mmrl::ControllerFile file = mmrl::ControllerFile::parse(std::move(copy), name ? name : "<memory>");
    return load_into(mmrl::RuntimeController::from_file(std::move(file)), out);
  });
}

void mmrl_controller_destroy(mmrl_controller* controller) { delete controller; }

const char* mmrl_controller_last_error(const mmrl_controller* controller) {
  return controller ? controller->error.c_str() : "controller is NULL";
}

mmrl_status mmrl_controller_num_joints(const mmrl_controller* controller, int32_t* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  *out = controller->c->num_joints();
  return MMRL_OK;
}

mmrl_status mmrl_controller_joint_name(const mmrl_controller* controller, int32_t joint, char* buffer, size_t size,
                                       size_t* needed) {
  if (controller == nullptr) return null_error("controller");
  const auto& names = controller->c->database().skeleton.names;
  if (joint < 0 || joint >= static_cast<int32_t>(names.size()))
    return fail(&controller->error, MMRL_ERROR_INVALID_ARGUMENT,
                "joint " + std::to_string(joint) + " is outside 0.." + std::to_string(names.size() - 1));
  const std::string& n = names[static_cast<size_t>(joint)];
  if (needed != nullptr) *needed = n.size() + 1;
  if (buffer == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "buffer is NULL");
  if (size < n.size() + 1)
    return fail(&controller->error, MMRL_ERROR_BUFFER_TOO_SMALL,
                "the name of joint " + std::to_string(joint) + " needs " + std::to_string(n.size() + 1) +
                    " bytes, the buffer holds " + std::to_string(size));
  std::memcpy(buffer, n.c_str(), n.size() + 1);
  return MMRL_OK;
}

mmrl_status mmrl_controller_joint_parent(const mmrl_controller* controller, int32_t joint, int32_t* out) {
  if (controller == nullptr) return null_error("controller");
  const auto& parents = controller->c->database().skeleton.parents;
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  if (joint < 0 || joint >= static_cast<int32_t>(parents.size()))
    return fail(&controller->error, MMRL_ERROR_INVALID_ARGUMENT,
                "joint " + std::to_string(joint) + " is outside 0.." + std::to_string(parents.size() - 1));
  *out = parents[static_cast<size_t>(joint)];
  return MMRL_OK;
}

mmrl_status mmrl_controller_fps(const mmrl_controller* controller, float* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  *out = controller->c->fps();
  return MMRL_OK;
}

mmrl_status mmrl_controller_frames_per_step(const mmrl_controller* controller, int32_t* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  *out = controller->c->task().frames_per_step;
  return MMRL_OK;
}

mmrl_status mmrl_controller_success_radius(const mmrl_controller* controller, float* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  *out = controller->c->task().success_radius;
  return MMRL_OK;
}

mmrl_status mmrl_controller_num_start_frames(const mmrl_controller* controller, int64_t* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  *out = static_cast<int64_t>(controller->c->database().valid_frames.size());
  return MMRL_OK;
}

mmrl_status mmrl_controller_start_frame(const mmrl_controller* controller, int64_t k, int64_t* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  const auto& v = controller->c->database().valid_frames;
  if (k < 0 || k >= static_cast<int64_t>(v.size()))
    return fail(&controller->error, MMRL_ERROR_INVALID_ARGUMENT,
                "k = " + std::to_string(k) + " is outside 0.." + std::to_string(v.size()) + " - 1");
  *out = v[static_cast<size_t>(k)];
  return MMRL_OK;
}

mmrl_status mmrl_controller_max_obstacles(const mmrl_controller* controller, int32_t* out) {
  if (controller == nullptr) return null_error("controller");
  if (out == nullptr) return fail(&controller->error, MMRL_ERROR_NULL, "out is NULL");
  *out = controller->c->task().num_obstacles;
  return MMRL_OK;
}

mmrl_status mmrl_character_create(mmrl_controller* controller, float x, float z, float yaw, int64_t start_frame,
                                  mmrl_character** out) {
  if (out == nullptr) return null_error("out");
  *out = nullptr;
  if (controller == nullptr) return null_error("controller");
  return guarded(&controller->error, [&] {
    auto h = std::make_unique<mmrl_character>();
    h->controller = controller->c;
    h->c = std::make_unique<mmrl::RuntimeCharacter>(controller->c, x, z, yaw, start_frame);
    *out = h.release();
    return MMRL_OK;
  });
}

void mmrl_character_destroy(mmrl_character* character) { delete character; }

const char* mmrl_character_last_error(const mmrl_character* character) {
  return character ? character->error.c_str() : "character is NULL";
}

mmrl_status mmrl_character_set_target(mmrl_character* character, float x, float z) {
  if (character == nullptr) return null_error("character");
  return guarded(&character->error, [&] {
    character->c->set_target(x, z);
    return MMRL_OK;
  });
}

mmrl_status mmrl_character_set_facing(mmrl_character* character, float yaw) {
  if (character == nullptr) return null_error("character");
  return guarded(&character->error, [&] {
    character->c->set_facing(yaw);
    return MMRL_OK;
  });
}

mmrl_status mmrl_character_set_stick(mmrl_character* character, float x, float z, float speed) {
  if (character == nullptr) return null_error("character");
  return guarded(&character->error, [&] {
    character->c->set_stick(x, z, speed);
    return MMRL_OK;
  });
}

mmrl_status mmrl_character_set_obstacles(mmrl_character* character, int32_t n, const float* centres,
                                         const float* half_sizes, const float* angles, const float* velocities) {
  if (character == nullptr) return null_error("character");
  if (n < 0) return fail(&character->error, MMRL_ERROR_INVALID_ARGUMENT, "n must be >= 0");
  if (n > 0 && (centres == nullptr || half_sizes == nullptr || angles == nullptr))
    return fail(&character->error, MMRL_ERROR_NULL, "centres, half_sizes and angles must not be NULL when n > 0");
  return guarded(&character->error, [&] {
    character->c->set_obstacles(n, centres, half_sizes, angles, velocities);
    return MMRL_OK;
  });
}

mmrl_status mmrl_character_set_request(mmrl_character* character, const char* request) {
  if (character == nullptr) return null_error("character");
  return guarded(&character->error, [&] {
    character->c->set_request(request ? request : "");
    return MMRL_OK;
  });
}

mmrl_status mmrl_character_update(mmrl_character* character, float dt, float* local_rotations,
                                  float* local_translations, int32_t capacity, float* root) {
  if (character == nullptr) return null_error("character");
  if (local_rotations == nullptr) return fail(&character->error, MMRL_ERROR_NULL, "local_rotations is NULL");
  const int J = character->controller->num_joints();
  if (capacity < J)
    return fail(&character->error, MMRL_ERROR_BUFFER_TOO_SMALL,
                "the buffers hold " + std::to_string(capacity) + " joints, the skeleton has " + std::to_string(J));
  return guarded(&character->error, [&] {
    const mmrl::RuntimePose& p = character->c->update(dt);
    std::memcpy(local_rotations, p.local_rotations, sizeof(float) * 4 * static_cast<size_t>(J));
    if (local_translations != nullptr)
      std::memcpy(local_translations, p.local_translations, sizeof(float) * 3 * static_cast<size_t>(J));
    if (root != nullptr) {
      root[0] = p.root.x;
      root[1] = p.root.z;
      root[2] = p.root.yaw;
    }
    return MMRL_OK;
  });
}

mmrl_status mmrl_character_frame(const mmrl_character* character, int64_t* frame, int32_t* transition) {
  if (character == nullptr) return null_error("character");
  if (frame != nullptr) *frame = character->c->pose().frame;
  if (transition != nullptr) *transition = character->c->last_decision().transition ? 1 : 0;
  return MMRL_OK;
}

mmrl_status mmrl_character_root(const mmrl_character* character, float* root) {
  if (character == nullptr) return null_error("character");
  if (root == nullptr) return null_error("root");
  const mmrl::RootState& r = character->c->character().root();
  root[0] = r.x;
  root[1] = r.z;
  root[2] = r.yaw;
  return MMRL_OK;
}

mmrl_status mmrl_character_last_decision(const mmrl_character* character, mmrl_decision* out) {
  if (character == nullptr) return null_error("character");
  if (out == nullptr) return null_error("out");
  const mmrl::RuntimeDecision& d = character->c->last_decision();
  out->count = d.count;
  out->frames_before = d.frames_before;
  out->match = d.match;
  out->transition = d.transition ? 1 : 0;
  out->root_x = d.root_before.x;
  out->root_z = d.root_before.z;
  out->root_yaw = d.root_before.yaw;
  out->target_x = d.target_x;
  out->target_z = d.target_z;
  out->cost = d.cost;
  return MMRL_OK;
}

}  // extern "C"

// The compressed controller's sections of a runtime file (docs/runtime.md, "Compressed
// controllers"): read_motion_source, the loader's one door to a source other than the database.
#include <cmath>
#include <memory>
#include <string>

#include "mmrl/compressed_source.hpp"
#include "mmrl/runtime.hpp"

namespace mmrl {

namespace {

// A compressed source with the networks and start states it reads (CompressedSource borrows them).
struct OwnedCompressedSource {
  CompressedModel model;
  std::vector<float> frame_states;
  std::unique_ptr<CompressedSource> source;
};

}  // namespace

std::shared_ptr<const MotionSource> read_motion_source(const ControllerFile& file, const Database& db,
                                                       const RuntimeTask& task, float* action_box) {
  if (!file.has("lmm.header")) return nullptr;  // the database's own motion
  constexpr int32_t kVersion = 1;
  const auto header = file.ints("lmm.header", {6});
  if (header[0] != kVersion)
    file.fail("compressed sections of version " + std::to_string(header[0]) + "; this runtime reads version " +
              std::to_string(kVersion));
  if (!task.config->request_groups.empty()) file.fail("a compressed controller keeps to no tags (task.request_groups)");
  auto owned = std::make_shared<OwnedCompressedSource>();
  CompressedModel* model = &owned->model;
  model->num_joints = header[1];
  model->latent = header[2];
  if (model->num_joints != db.num_joints)
    file.fail("the compressed networks are for " + std::to_string(header[1]) + " joints, the skeleton has " +
              std::to_string(db.num_joints));
  if (model->latent < 1 || model->latent > 4096) file.fail("lmm.header: latent size out of range");
  Mlp* nets[3] = {&model->decompressor, &model->stepper, &model->projector};
  const char* names[3] = {"decompressor", "stepper", "projector"};
  for (int n = 0; n < 3; ++n) {
    if (header[3 + n] < 1 || header[3 + n] > 64) file.fail(std::string("lmm.header: ") + names[n] + " layers out of range");
    for (int k = 0; k < header[3 + n]; ++k) {
      const std::string base = std::string("lmm.") + names[n] + "." + std::to_string(k);
      const FileSection& w = file.section(base + ".weight");
      if (w.shape.size() != 2) file.fail("section '" + base + ".weight' must be 2-d (out x in)");
      Mlp::Layer layer;
      layer.out = static_cast<int>(w.shape[0]);
      layer.in = static_cast<int>(w.shape[1]);
      if (w.type == SectionType::kFloat16) {  // what mmrl export writes: the core's own precision
        const std::vector<uint16_t> h = file.halves(base + ".weight", {w.shape[0], w.shape[1]});
        layer.weight.resize(h.size());
        for (size_t k = 0; k < h.size(); ++k) layer.weight[k] = float16_to_float(h[k]);  // exact
      } else {
        layer.weight = file.floats(base + ".weight", {w.shape[0], w.shape[1]});
      }
      layer.bias = file.floats(base + ".bias", {w.shape[0]});
      nets[n]->layers.push_back(std::move(layer));
    }
  }
  model->y_mean = file.floats("lmm.y_mean", {model->pose_dim()});
  model->y_std = file.floats("lmm.y_std", {model->pose_dim()});
  model->z_mean = file.floats("lmm.z_mean", {model->latent});
  model->z_std = file.floats("lmm.z_std", {model->latent});
  if (file.has("lmm.fixed_joints")) {
    model->fixed_joints = file.bytes("lmm.fixed_joints", {model->num_joints});
    model->fixed_translations = file.floats("lmm.fixed_translations", {model->num_joints, 3});
  }
  try {
    model->prepare();
  } catch (const std::invalid_argument& e) {
    file.fail(std::string("the compressed networks do not fit: ") + e.what());
  }
  owned->frame_states = file.floats("lmm.frame_states", {db.num_frames, model->state_dim()});
  for (float v : owned->frame_states)
    if (!std::isfinite(v)) file.fail("section 'lmm.frame_states' is not finite");
  const auto box = file.floats("lmm.action_box", {2, kTrajectoryDim});
  for (int k = 0; k < kTrajectoryDim; ++k)
    if (!(box[k] <= box[kTrajectoryDim + k])) file.fail("section 'lmm.action_box': low must be <= high");
  std::copy(box.begin(), box.end(), action_box);
  owned->source = std::make_unique<CompressedSource>(db, *model, owned->frame_states.data());
  return std::shared_ptr<const MotionSource>(owned, owned->source.get());  // keeps `owned` alive
}

}  // namespace mmrl

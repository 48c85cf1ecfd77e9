// The arrive task in the engine runtime (runtime_task.hpp): the task's own observation and
// decision; the character's target and its facing (set_facing, radians), relative to it.
#include <cmath>
#include <stdexcept>

#include "mmrl/runtime_task.hpp"
#include "mmrl/tasks/arrive.hpp"

namespace mmrl {

namespace {

class ArriveCharacterTask final : public CharacterTaskOf<ArriveTask> {
 public:
  using CharacterTaskOf::CharacterTaskOf;
  bool takes_facing() const override { return true; }
  void set_facing(float yaw) override {
    if (!std::isfinite(yaw)) throw std::invalid_argument("facing must be finite (radians)");
    facing_ = yaw;
  }
  void sync(const RootState& root, int64_t frame, float target_x, float target_z, const RuntimeObstacles& o,
            int64_t decision) override {
    if (!std::isfinite(facing_))
      throw std::invalid_argument("this controller's task (arrive) needs a facing: set it with set_facing (radians)");
    CharacterTaskOf::sync(root, frame, target_x, target_z, o, decision);
    task_.set_facing(0, facing_);  // the task's frame is the world's turned by nothing: a world yaw
  }

 private:
  float facing_ = NAN;
};

}  // namespace

RuntimeTaskType arrive_runtime_task() {
  RuntimeTaskType t = runtime_task_of<ArriveTask>();
  t.make_task = [](const Database& db, const Matcher& matcher, const RuntimeTask& task) -> std::unique_ptr<CharacterTask> {
    return std::make_unique<ArriveCharacterTask>(db, matcher, task);
  };
  return t;
}

}  // namespace mmrl

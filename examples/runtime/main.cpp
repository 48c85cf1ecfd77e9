// mmrl_runtime_example: drive N characters with an exported controller (mmrl export RUN -o
// controller.mmrl) through a scripted list of targets, with no Python and no torch, and write
// the JSON trace `mmrl play --trace` writes: one line per decision step, per character,
//   {"character": i, "t": seconds, "root": [x, z, yaw], "target": [x, z], "frame": match,
//    "transition": bool}
// (root: before the decision; frame: the matched database frame; "character" is added
// because there are several).
//
// Character i starts on valid frame (i * 97) mod (valid frames) at (2 * (i % 8), 2 * (i / 8))
// facing +Z, and walks to its start + each scripted target in turn: at a decision, a root
// within the task's success_radius of its target moves it on to the next (the list repeats).
//
// usage: mmrl_runtime_example CONTROLLER [--characters N] [--decisions D] [--targets "x,z;x,z;..."]
//                             [--trace FILE] [--request "style=elderly"] [--obstacles K]
// --request: every character keeps to the clips carrying these tags (docs/styles.md).
// --obstacles: an obstacles controller's characters each walk among K moving rectangles of their
// own (the task's stage 10: sides 0.25-3 m, speeds up to 0.5 m/s, bouncing inside 10 m of the
// start), set before every decision, so the time includes the sensors and the collision-aware
// search in a crowd.
// -h, --help: the usage on stdout, exit 0.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "mmrl/runtime.hpp"

namespace {

const char* const kUsage =
    "usage: mmrl_runtime_example CONTROLLER [--characters N] [--decisions D] [--targets \"x,z;x,z;...\"]\n"
    "                            [--trace FILE] [--request TAGS] [--obstacles K]\n"
    "\n"
    "Drives N characters with an exported controller (mmrl export RUN -o controller.mmrl) through\n"
    "a scripted list of targets, without Python, and prints the time per character per frame.\n"
    "\n"
    "  CONTROLLER       the controller file (.mmrl)\n"
    "  --characters N   characters, character i starting at (2 (i % 8), 2 (i / 8)) m facing +Z (default 1)\n"
    "  --decisions D    decisions per character (default 100)\n"
    "  --targets LIST   targets relative to each start, meters, \"x,z;x,z;...\" (default \"0,4;4,4;4,-2;-3,0\");\n"
    "                   the next one once the character is within the task's success radius\n"
    "  --trace FILE     write the JSON trace of `mmrl play --trace` (one line per decision per character)\n"
    "  --request TAGS   keep to the clips carrying these tags, e.g. \"style=elderly & gait=walk\"\n"
    "  --obstacles K    an obstacles controller: K moving rectangles around each character (0.25-3 m,\n"
    "                   up to 0.5 m/s, within 10 m of its start), set before every decision\n"
    "  -h, --help       this message\n";

struct Options {
  std::string controller, trace, request;
  bool help = false;
  int characters = 1;
  int obstacles = 0;
  long decisions = 100;
  std::vector<std::pair<float, float>> targets = {{0.0f, 4.0f}, {4.0f, 4.0f}, {4.0f, -2.0f}, {-3.0f, 0.0f}};
};

std::vector<std::pair<float, float>> parse_targets(const std::string& text) {
  std::vector<std::pair<float, float>> out;
  std::stringstream all(text);
  std::string item;
  while (std::getline(all, item, ';')) {
    float x, z;
    char comma;
    std::stringstream one(item);
    if (!(one >> x >> comma >> z) || comma != ',' || !std::isfinite(x) || !std::isfinite(z))
      throw std::invalid_argument("--targets: expected \"x,z;x,z;...\", got \"" + item + "\"");
    out.emplace_back(x, z);
  }
  if (out.empty()) throw std::invalid_argument("--targets: no targets");
  return out;
}

Options parse(int argc, char** argv) {
  Options o;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    auto value = [&]() -> std::string {
      if (k + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++k];
    };
    if (a == "-h" || a == "--help") {
      o.help = true;
      return o;
    }
    if (a == "--characters") o.characters = std::stoi(value());
    else if (a == "--decisions") o.decisions = std::stol(value());
    else if (a == "--targets") o.targets = parse_targets(value());
    else if (a == "--trace") o.trace = value();
    else if (a == "--request") o.request = value();
    else if (a == "--obstacles") o.obstacles = std::stoi(value());
    else if (!a.empty() && a[0] == '-') throw std::invalid_argument("unknown option " + a);
    else if (o.controller.empty()) o.controller = a;
    else throw std::invalid_argument("one controller file only");
  }
  if (o.controller.empty())
    throw std::invalid_argument("usage: mmrl_runtime_example CONTROLLER [options] (--help for the options)");
  if (o.characters < 1 || o.decisions < 1) throw std::invalid_argument("--characters and --decisions must be >= 1");
  if (o.obstacles < 0) throw std::invalid_argument("--obstacles must be >= 0");
  return o;
}

// K moving rectangles around one character's start (stage 10 of the obstacles task), in world
// meters: they move by their velocity and bounce inside the square of kHalf around the start.
struct Crowd {
  static constexpr float kHalf = 10.0f;
  float x0, z0;
  std::vector<float> centres, half_sizes, angles, velocities;
  Crowd(int k, float x, float z, std::mt19937& rng) : x0(x), z0(z) {
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int i = 0; i < k; ++i) {
      float cx, cz;
      do {  // none on the character's start
        cx = (2 * u(rng) - 1) * kHalf;
        cz = (2 * u(rng) - 1) * kHalf;
      } while (std::hypot(cx, cz) < 2.0f);
      const float heading = 6.2831853f * u(rng), speed = 0.5f * u(rng);
      centres.insert(centres.end(), {x0 + cx, z0 + cz});
      half_sizes.insert(half_sizes.end(), {0.125f + 1.375f * u(rng), 0.125f + 1.375f * u(rng)});
      angles.push_back(6.2831853f * u(rng) - 3.1415927f);
      velocities.insert(velocities.end(), {speed * std::sin(heading), speed * std::cos(heading)});
    }
  }
  void move(float seconds) {
    for (size_t i = 0; i < angles.size(); ++i)
      for (int a = 0; a < 2; ++a) {
        float& c = centres[2 * i + a];
        float& v = velocities[2 * i + a];
        const float o = a == 0 ? x0 : z0;
        c += v * seconds;
        if (std::abs(c - o) > kHalf) {  // mirrored back inside, that velocity component flips
          c = o + std::copysign(2 * kHalf, c - o) - (c - o);
          v = -v;
        }
      }
  }
};

void write_line(FILE* f, int character, const mmrl::RuntimeDecision& d, float fps) {
  std::fprintf(f,
               "{\"character\": %d, \"t\": %.4f, \"root\": [%.5f, %.5f, %.5f], \"target\": [%.5f, %.5f], "
               "\"frame\": %lld, \"transition\": %s}\n",
               character, static_cast<double>(d.frames_before) / fps, d.root_before.x, d.root_before.z,
               d.root_before.yaw, d.target_x, d.target_z, static_cast<long long>(d.match),
               d.transition ? "true" : "false");
}

int run(const Options& o) {
  auto t0 = std::chrono::steady_clock::now();
  const auto controller = mmrl::RuntimeController::load(o.controller);
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const mmrl::Database& db = controller->database();
  std::vector<int64_t> valid;
  for (int64_t f = 0; f < db.num_frames; ++f)
    if (db.valid[f]) valid.push_back(f);
  std::vector<std::unique_ptr<mmrl::RuntimeCharacter>> chars;
  std::vector<size_t> next(o.characters, 0);
  std::vector<std::pair<float, float>> origin;
  std::vector<Crowd> crowds;
  std::mt19937 rng(7);
  for (int i = 0; i < o.characters; ++i) {
    origin.emplace_back(2.0f * (i % 8), 2.0f * (i / 8));
    chars.push_back(std::make_unique<mmrl::RuntimeCharacter>(controller, origin[i].first, origin[i].second, 0.0f,
                                                             valid[(static_cast<size_t>(i) * 97) % valid.size()]));
    chars[i]->set_target(origin[i].first + o.targets[0].first, origin[i].second + o.targets[0].second);
    if (chars[i]->takes_facing()) chars[i]->set_facing(0.0f);  // an arrive controller: face +Z at each target
    if (!o.request.empty()) chars[i]->set_request(o.request);
    if (o.obstacles > 0) crowds.emplace_back(o.obstacles, origin[i].first, origin[i].second, rng);
  }
  std::unique_ptr<FILE, int (*)(FILE*)> trace(o.trace.empty() ? nullptr : std::fopen(o.trace.c_str(), "w"),
                                              &std::fclose);
  if (!o.trace.empty() && !trace) throw std::runtime_error(o.trace + ": cannot write the trace");
  const float dt = 1.0f / controller->fps(), radius = controller->task().success_radius;
  const int F = controller->task().frames_per_step;
  t0 = std::chrono::steady_clock::now();
  for (long step = 0; step < o.decisions; ++step) {
    for (int i = 0; i < o.characters; ++i) {
      mmrl::RuntimeCharacter& c = *chars[i];
      const mmrl::RuntimeDecision& d = c.last_decision();
      // A decision comes at the next frame: move on to the next target if this one is reached.
      const auto& r = c.character().root();
      const auto& tg = o.targets[next[i] % o.targets.size()];
      if (std::hypot(origin[i].first + tg.first - r.x, origin[i].second + tg.second - r.z) < radius) {
        const auto& nt = o.targets[++next[i] % o.targets.size()];
        c.set_target(origin[i].first + nt.first, origin[i].second + nt.second);
      }
      if (o.obstacles > 0) {  // the world moves on, and the character sees it at its next decision
        Crowd& w = crowds[i];
        if (step > 0) w.move(F * dt);
        c.set_obstacles(o.obstacles, w.centres.data(), w.half_sizes.data(), w.angles.data(), w.velocities.data());
      }
      for (int k = 0; k < F; ++k) c.update(dt);
      if (trace) write_line(trace.get(), i, d, controller->fps());
    }
  }
  const double run_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::fprintf(stderr, "loaded %s in %.3f s (%d frames, %d joints); %d characters x %ld decisions in %.3f s: "
               "%.2f us per character per frame\n", o.controller.c_str(), load_s, db.num_frames, db.num_joints,
               o.characters, o.decisions, run_s, 1e6 * run_s / (double(o.characters) * o.decisions * F));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    if (o.help) {
      std::fputs(kUsage, stdout);
      return 0;
    }
    return run(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mmrl_runtime_example: error: %s\n", e.what());
    return 2;
  }
}

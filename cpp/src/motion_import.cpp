#include "mmrl/motion_import.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include "mmrl/skeleton.hpp"

namespace mmrl {

namespace {

// Up to n frame indices spread evenly over [0, F).
std::vector<int> sample_frames(int num_frames, int n) {
  std::vector<int> out;
  const int k = std::min(num_frames, n);
  for (int i = 0; i < k; ++i) out.push_back(k > 1 ? static_cast<int>(static_cast<int64_t>(i) * (num_frames - 1) / (k - 1)) : 0);
  return out;
}

void frame_positions(const Motion& m, int f, std::vector<float>& gp, std::vector<float>& gr) {
  const int J = m.skeleton.num_joints();
  gp.resize(static_cast<size_t>(J) * 3);
  gr.resize(static_cast<size_t>(J) * 4);
  const size_t o = static_cast<size_t>(f) * J;
  pose_forward_kinematics(m.skeleton.parents, &m.translations[o * 3], &m.rotations[o * 4], gp.data(), gr.data());
}

Vec3 at(const std::vector<float>& gp, int j) { return Vec3(gp[j * 3], gp[j * 3 + 1], gp[j * 3 + 2]); }

float median(std::vector<float> v) {
  if (v.empty()) return 0.0f;
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  if (v.size() % 2) return v[h];
  const float hi = v[h];
  return 0.5f * (hi + *std::max_element(v.begin(), v.begin() + h));
}

// 1 / fps rounded to 7 significant digits, as bvh_write (and most exporters) store Frame
// Time: a resampled clip then has the rate it would have if written at that rate and read
// back. It matters because features depend on the rate's last digits: the heading
// smoothing radius ceil(3 * 0.3 s * fps) is 27 frames at 29.9999998 fps (float 1/30) but 28
// at 30.0000019 fps (0.03333333 s), which moves features by up to 2e-3.
float written_frame_time(float fps) {
  char text[32];
  std::snprintf(text, sizeof text, "%.7g", 1.0 / static_cast<double>(fps));
  return std::strtof(text, nullptr);
}

}  // namespace

UpAxis motion_detect_up_axis(const Motion& m) {
  if (m.num_frames <= 0 || m.skeleton.num_joints() == 0) return UpAxis::Y;
  JointRoles roles;
  try {
    roles = skeleton_find_roles(m.skeleton);
  } catch (const RoleError&) {
    return UpAxis::Y;
  }
  std::vector<float> gp, gr;
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (int f : sample_frames(m.num_frames, 16)) {
    frame_positions(m, f, gp, gr);
    const Vec3 feet = 0.5f * (at(gp, roles.foot[0]) + at(gp, roles.foot[1]));
    up += (at(gp, roles.hips) - feet).cast<double>();
  }
  Eigen::Index axis = 0;
  up.cwiseAbs().maxCoeff(&axis);
  return (axis == 2 && up.z() > 0) ? UpAxis::Z : UpAxis::Y;
}

void motion_rotate_z_up_to_y_up(Motion& m) {
  // -90 degrees about X maps +Z (up in the file) to +Y and +Y to -Z.
  const Quat r(Eigen::AngleAxisf(-0.5f * kPi, Vec3::UnitX()));
  auto rotate = [](const Vec3& v) { return Vec3(v.x(), v.z(), -v.y()); };
  const int J = m.skeleton.num_joints();
  for (int j = 0; j < J; ++j) {
    if (m.skeleton.parents[j] >= 0) continue;
    m.skeleton.offsets[j] = rotate(m.skeleton.offsets[j]);
    for (int f = 0; f < m.num_frames; ++f) {
      const size_t o = static_cast<size_t>(f) * J + j;
      float* t = &m.translations[o * 3];
      const Vec3 v = rotate(Vec3(t[0], t[1], t[2]));
      t[0] = v.x();
      t[1] = v.y();
      t[2] = v.z();
      quat_store((r * quat_load(&m.rotations[o * 4])).normalized(), &m.rotations[o * 4]);
    }
  }
}

float motion_nominal_fps(const Motion& m) {
  if (!(m.frame_time > 0)) return 0.0f;
  const double fps = 1.0 / static_cast<double>(m.frame_time);
  const double whole = std::round(fps);
  return static_cast<float>(whole > 0 && std::fabs(fps - whole) <= 1e-4 * fps ? whole : fps);
}

bool motion_needs_resample(const Motion& m, float fps) {
  return std::fabs(motion_nominal_fps(m) - fps) > 1e-4f * fps;
}

// 2^28 frames: 103 days at 30 fps, well inside the int frame count.
constexpr double kMaxResampledFrames = 268435456.0;

Motion motion_resample(const Motion& m, float fps) {
  if (!(fps > 0) || !std::isfinite(fps)) throw std::invalid_argument("resample: fps must be positive, got " + std::to_string(fps));
  if (m.num_frames <= 0) throw std::invalid_argument("resample: '" + m.source + "' has no frames");
  const int J = m.skeleton.num_joints();
  // Input frames per output frame, from the nominal rates so that 60 -> 30 is exactly 2.
  const double step = static_cast<double>(motion_nominal_fps(m)) / fps;
  // In double first: a slow clip resampled to a fast rate can ask for more frames than an int
  // holds (UB in the cast); more than kMaxResampledFrames is refused.
  const double frames_d = std::floor((m.num_frames - 1) / step + 1e-6) + 1;
  if (!(frames_d <= kMaxResampledFrames))
    throw std::invalid_argument("resample: '" + m.source + "' at " + std::to_string(fps) + " fps would have " +
                                std::to_string(frames_d) + " frames (at most " + std::to_string(kMaxResampledFrames) + ")");
  const int frames = static_cast<int>(frames_d);
  Motion out;
  out.skeleton = m.skeleton;
  out.source = m.source;
  out.frame_time = written_frame_time(fps);
  out.scale = m.scale;
  out.source_fps = m.source_fps;
  out.source_up = m.source_up;
  out.num_frames = frames;
  out.translations.resize(static_cast<size_t>(frames) * J * 3);
  out.rotations.resize(static_cast<size_t>(frames) * J * 4);
  for (int k = 0; k < frames; ++k) {
    const double s = k * step;
    int i = static_cast<int>(std::floor(s + 1e-9));
    double a = s - i;
    if (a < 1e-9) a = 0.0;  // on an input frame: copy it bit for bit
    if (i >= m.num_frames - 1) {
      i = m.num_frames - 1;
      a = 0.0;
    }
    const size_t o0 = static_cast<size_t>(i) * J, ok = static_cast<size_t>(k) * J;
    if (a == 0.0) {
      std::copy_n(&m.translations[o0 * 3], J * 3, &out.translations[ok * 3]);
      std::copy_n(&m.rotations[o0 * 4], J * 4, &out.rotations[ok * 4]);
      continue;
    }
    const size_t o1 = o0 + J;
    for (int c = 0; c < J * 3; ++c)
      out.translations[ok * 3 + c] =
          static_cast<float>((1.0 - a) * m.translations[o0 * 3 + c] + a * m.translations[o1 * 3 + c]);
    for (int j = 0; j < J; ++j) {
      const Eigen::Quaterniond q0 = quat_load(&m.rotations[(o0 + j) * 4]).cast<double>();
      const Eigen::Quaterniond q1 = quat_load(&m.rotations[(o1 + j) * 4]).cast<double>();
      quat_store(q0.slerp(a, q1).normalized().cast<float>(), &out.rotations[(ok + j) * 4]);
    }
  }
  return out;
}

MotionPlausibility motion_plausibility(const Motion& m) {
  MotionPlausibility p;
  const int J = m.skeleton.num_joints(), F = m.num_frames;
  if (F <= 0 || J == 0) return p;
  // The body: every joint but the roots, which are often a marker on the ground that never
  // moves (Bandai's joint_Root stays at the origin while the hips walk away).
  std::vector<int> body;
  for (int j = 0; j < J; ++j)
    if (m.skeleton.parents[j] >= 0) body.push_back(j);
  if (body.empty()) body.push_back(0);
  const float fps = m.fps();
  p.seconds = F > 1 && fps > 0 ? (F - 1) / fps : 0.0f;
  std::vector<float> gp, gr, heights, extents;
  for (int f : sample_frames(F, 16)) {
    frame_positions(m, f, gp, gr);
    float lo = INFINITY, hi = -INFINITY, widest = 0.0f;
    for (size_t a = 0; a < body.size(); ++a) {
      const int j = body[a];
      lo = std::min(lo, gp[j * 3 + 1]);
      hi = std::max(hi, gp[j * 3 + 1]);
      for (size_t b = 0; b < a; ++b) {
        const int k = body[b];
        widest = std::max(widest, std::hypot(gp[j * 3] - gp[k * 3], gp[j * 3 + 2] - gp[k * 3 + 2]));
      }
    }
    heights.push_back(hi - lo);
    extents.push_back(widest);
  }
  p.height = median(heights);
  p.horizontal_extent = median(extents);
  // The body's centroid per frame: a rough centre of mass.
  std::vector<Vec3> centre(F);
  for (int f = 0; f < F; ++f) {
    frame_positions(m, f, gp, gr);
    Vec3 c = Vec3::Zero();
    for (int j : body) c += at(gp, j);
    centre[f] = c / static_cast<float>(body.size());
  }
  float lo = INFINITY, hi = -INFINITY;
  std::vector<float> speeds;
  for (int f = 0; f < F; ++f) {
    lo = std::min(lo, centre[f].y());
    hi = std::max(hi, centre[f].y());
    if (f == 0) continue;
    const float step = std::hypot(centre[f].x() - centre[f - 1].x(), centre[f].z() - centre[f - 1].z());
    p.horizontal_path += step;
    speeds.push_back(step * fps);
  }
  p.vertical_travel = hi - lo;
  p.median_horizontal_speed = median(speeds);
  return p;
}

}  // namespace mmrl

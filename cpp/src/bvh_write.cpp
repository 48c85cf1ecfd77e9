// Motion -> BVH text (see bvh_write in bvh.hpp).
#include <iomanip>
#include <sstream>

#include "mmrl/bvh.hpp"

namespace mmrl {

namespace {

const char* channel_name(Channel c) {
  static const char* kNames[6] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};
  return kNames[static_cast<int>(c)];
}

// Euler angles (degrees) for R = R_a0 * R_a1 * R_a2 with axes given in order.
Eigen::Vector3d euler_from_quat(const Eigen::Quaterniond& q, const int axes[3]) {
  // Eigen's eulerAngles(a0, a1, a2) returns angles for R = R_a0(x) R_a1(y) R_a2(z).
  const Eigen::Matrix3d R = q.toRotationMatrix();
  Eigen::Vector3d e = R.eulerAngles(axes[0], axes[1], axes[2]);
  // Prefer the solution with the smallest middle-angle magnitude for continuity.
  return e * (180.0 / M_PI);
}

void write_joint(std::ostringstream& os, const Skeleton& sk, int j, int depth, float inv_scale) {
  const std::string ind(static_cast<size_t>(depth), '\t');
  os << ind << (sk.parents[j] < 0 ? "ROOT " : "JOINT ") << sk.names[j] << "\n" << ind << "{\n";
  const Vec3 o = sk.offsets[j] * inv_scale;
  os << ind << "\tOFFSET " << o.x() << " " << o.y() << " " << o.z() << "\n";
  os << ind << "\tCHANNELS " << sk.channels[j].size();
  for (Channel c : sk.channels[j]) os << " " << channel_name(c);
  os << "\n";
  for (int k = 0; k < sk.num_joints(); ++k)
    if (sk.parents[k] == j) write_joint(os, sk, k, depth + 1, inv_scale);
  if (sk.has_end_site[j]) {
    const Vec3 e = sk.end_sites[j] * inv_scale;
    os << ind << "\tEnd Site\n" << ind << "\t{\n" << ind << "\t\tOFFSET " << e.x() << " " << e.y() << " " << e.z() << "\n" << ind << "\t}\n";
  }
  os << ind << "}\n";
}

}  // namespace

std::string bvh_write(const Motion& m) {
  const Skeleton& sk = m.skeleton;
  const int J = sk.num_joints();
  const float inv_scale = m.scale > 0 ? 1.0f / m.scale : 1.0f;
  std::ostringstream os;
  os << std::setprecision(7);
  os << "HIERARCHY\n";
  // Joints are written in depth-first order, which is the order BVH files store them in;
  // a Motion parsed from BVH already has that order.
  for (int j = 0; j < J; ++j)
    if (sk.parents[j] < 0) write_joint(os, sk, j, 0, inv_scale);
  os << "MOTION\nFrames: " << m.num_frames << "\nFrame Time: " << m.frame_time << "\n";
  for (int f = 0; f < m.num_frames; ++f) {
    bool first = true;
    for (int j = 0; j < J; ++j) {
      const size_t o = static_cast<size_t>(f) * J + j;
      const float* t = &m.translations[o * 3];
      int axes[3];
      int na = 0;
      for (Channel c : sk.channels[j])
        if (c >= Channel::Xrotation) axes[na++] = static_cast<int>(c) - 3;
      Eigen::Vector3d e = Eigen::Vector3d::Zero();
      if (na == 3) e = euler_from_quat(quat_load(&m.rotations[o * 4]).cast<double>(), axes);
      int ri = 0;
      for (Channel c : sk.channels[j]) {
        double v;
        if (c < Channel::Xrotation) v = t[static_cast<int>(c)] * inv_scale;
        else v = e[ri++];
        os << (first ? "" : " ") << v;
        first = false;
      }
    }
    os << "\n";
  }
  return os.str();
}

}  // namespace mmrl

#include "fisheye_mapping/core/detection/vehicle_motion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>

namespace fisheye_mapping {
namespace {

// The camera's viewing direction in the world's horizontal plane (unit), none
// when it looks nearly straight up or down.
std::optional<Eigen::Vector3d> horizontalViewDirection(const Eigen::Isometry3d& T_W_C) {
  Eigen::Vector3d f = T_W_C.linear().col(2);
  f.z() = 0.0;
  if (f.norm() < 0.1) return std::nullopt;
  return Eigen::Vector3d(f.normalized());
}

}  // namespace

const char* toString(VehicleMotion m) {
  switch (m) {
    case VehicleMotion::Moving:
      return "moving";
    case VehicleMotion::Parked:
      return "parked";
    default:
      return "undecided";
  }
}

VehicleMotionTracker::VehicleMotionTracker(const VehicleMotionConfig& config) : config_(config) {}

void VehicleMotionTracker::reset() {
  tracks_.clear();
  ghosts_.clear();
  past_.clear();
  last_stamp_ = -std::numeric_limits<double>::infinity();
}

bool VehicleMotionTracker::Track::fit(Eigen::Vector2d* velocity, double* stt, double* sigma) const {
  const size_t n = history.size();
  if (n < 2) return false;
  // Least-squares velocity of x(t), y(t): less noisy than the end points.
  double mt = 0.0;
  Eigen::Vector2d mp = Eigen::Vector2d::Zero();
  for (const auto& h : history) {
    mt += h.first;
    mp += h.second.head<2>();
  }
  mt /= n;
  mp /= double(n);
  *stt = 0.0;
  Eigen::Vector2d stp = Eigen::Vector2d::Zero();
  for (const auto& h : history) {
    *stt += (h.first - mt) * (h.first - mt);
    stp += (h.first - mt) * (h.second.head<2>() - mp);
  }
  if (!(*stt > 0.0)) return false;
  *velocity = stp / *stt;
  // Residual scatter per axis (two parameters per axis fitted); 0 with two points.
  double ss = 0.0;
  for (const auto& h : history) ss += (h.second.head<2>() - mp - *velocity * (h.first - mt)).squaredNorm();
  *sigma = n > 2 ? std::sqrt(ss / (2.0 * double(n - 2))) : 0.0;
  return true;
}

double VehicleMotionTracker::Track::speed() const {
  Eigen::Vector2d v;
  double stt, sigma;
  return fit(&v, &stt, &sigma) ? v.norm() : std::numeric_limits<double>::quiet_NaN();
}

double VehicleMotionTracker::positionNoise(const Eigen::Vector3d& p_W, const Eigen::Isometry3d& T_W_C) const {
  return noiseAt((p_W - T_W_C.translation()).norm());
}

double VehicleMotionTracker::noiseAt(double range) const {
  // Stereo depth error grows with the square of the range.
  const double r = range / 10.0;
  return config_.position_noise * std::max(1.0, r * r);
}

double VehicleMotionTracker::Track::speedError() const {
  Eigen::Vector2d v;
  double stt, sigma;
  if (!fit(&v, &stt, &sigma)) return std::numeric_limits<double>::infinity();
  double noise2 = 0.0;
  for (double s : noise) noise2 += s * s;
  const double expected = std::sqrt(noise2 / std::max<size_t>(1, noise.size()));
  return std::max(expected, sigma) / std::sqrt(stt);
}

bool VehicleMotionTracker::alongHeading(const Track& tr, const Eigen::Isometry3d& T_W_C) const {
  Eigen::Vector2d velocity;
  double stt, sigma;
  if (!tr.fit(&velocity, &stt, &sigma)) return false;
  const std::optional<Eigen::Vector3d> fwd = horizontalViewDirection(T_W_C);
  if (!fwd) return false;  // looking up or down: no heading
  // The velocity across the heading: less than half the moving speed.
  return std::abs(fwd->x() * velocity.y() - fwd->y() * velocity.x()) < 0.5 * config_.moving_speed;
}

std::vector<Eigen::AlignedBox3d> VehicleMotionTracker::ghostRegions() const {
  std::vector<Eigen::AlignedBox3d> out;
  for (const Ghost& g : ghosts_) out.push_back(g.region);
  return out;
}

std::optional<Eigen::Vector3d> VehicleMotionTracker::place(const Detection& box, int image_w, int image_h,
                                                           const cv::Mat& depth, const CameraModel& camera,
                                                           const Eigen::Isometry3d& T_W_C,
                                                           std::vector<Eigen::Vector3d>* body_C) const {
  if (body_C) body_C->clear();
  if (!std::isfinite(box.x_min) || !std::isfinite(box.y_min) || !std::isfinite(box.x_max) || !std::isfinite(box.y_max))
    return std::nullopt;
  const double sx = double(depth.cols) / image_w, sy = double(depth.rows) / image_h;
  // The inner part: a fifth off each side and the top, a quarter off the
  // bottom (the road under the body).
  const double bw = (box.x_max - box.x_min) * sx, bh = (box.y_max - box.y_min) * sy;
  if (!(bw > 0.0) || !(bh > 0.0)) return std::nullopt;
  const int u0 = std::max(0, int(std::ceil(box.x_min * sx + 0.2 * bw)));
  const int u1 = std::min(depth.cols - 1, int(std::floor(box.x_max * sx - 0.2 * bw)));
  const int v0 = std::max(0, int(std::ceil(box.y_min * sy + 0.2 * bh)));
  const int v1 = std::min(depth.rows - 1, int(std::floor(box.y_max * sy - 0.25 * bh)));
  if (u1 < u0 || v1 < v0) return std::nullopt;
  // At most about 40 x 40 samples per box.
  const int step = std::max(1, std::max(u1 - u0, v1 - v0) / 40);
  std::vector<std::pair<float, Eigen::Vector3d>> pts;  // (range, camera-frame point)
  for (int v = v0; v <= v1; v += step) {
    const float* d = depth.ptr<float>(v);
    for (int u = u0; u <= u1; u += step) {
      const float r = d[u];
      if (!(r > 0.0f) || !(r <= config_.max_range)) continue;
      Eigen::Vector3d ray;
      if (!camera.unproject(Eigen::Vector2d(u + 0.5, v + 0.5), &ray)) continue;
      pts.emplace_back(r, r * ray.normalized());
    }
  }
  if (static_cast<int>(pts.size()) < config_.min_points) return std::nullopt;
  // The body: the nearest cluster of ranges (up to 2.5 m beyond the 20th
  // percentile, a car's depth seen from any side).
  std::vector<float> ranges;
  ranges.reserve(pts.size());
  for (const auto& p : pts) ranges.push_back(p.first);
  const size_t q = ranges.size() / 5;
  std::nth_element(ranges.begin(), ranges.begin() + q, ranges.end());
  const float limit = ranges[q] + 2.5f;
  // Along the camera's horizontal viewing direction the face toward the
  // camera (the 20th percentile), across it and in height the median: the
  // near face stays put while more of the flank comes into view as the ego
  // drives up (the median slid forward with it).
  const std::optional<Eigen::Vector3d> view = horizontalViewDirection(T_W_C);
  const bool level = view.has_value();
  const Eigen::Vector3d fwd = level ? *view : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d side(-fwd.y(), fwd.x(), 0.0);
  std::vector<double> as, ls, zs;
  for (const auto& p : pts) {
    if (p.first > limit) continue;
    if (body_C) body_C->push_back(p.second);
    const Eigen::Vector3d w = T_W_C * p.second;
    as.push_back(fwd.dot(w));
    ls.push_back(side.dot(w));
    zs.push_back(w.z());
  }
  if (static_cast<int>(as.size()) < config_.min_points) return std::nullopt;
  auto quantile = [](std::vector<double>& v, double q) {
    const size_t k = static_cast<size_t>(q * (v.size() - 1) + 0.5);
    std::nth_element(v.begin(), v.begin() + k, v.end());
    return v[k];
  };
  const double a = quantile(as, level ? 0.2 : 0.5), l = quantile(ls, 0.5), z = quantile(zs, 0.5);
  const Eigen::Vector3d xy = a * fwd + l * side;
  return Eigen::Vector3d(xy.x(), xy.y(), z);
}

double VehicleMotionTracker::staticShare(const std::vector<Eigen::Vector3d>& body_C, const Eigen::Isometry3d& T_W_C,
                                         const cv::Mat& past, const CameraModel& camera,
                                         const Eigen::Isometry3d& T_W_P) const {
  const Eigen::Isometry3d T_P_C = T_W_P.inverse() * T_W_C;
  int seen = 0, agree = 0;
  for (const Eigen::Vector3d& p : body_C) {
    const Eigen::Vector3d q = T_P_C * p;
    Eigen::Vector2d px;
    if (!camera.project(q, &px) || !camera.isInImage(px)) continue;
    const int u = int(std::floor(px.x())), v = int(std::floor(px.y()));
    const double r = q.norm();
    const double tolerance = 2.0 * noiseAt(r);
    double best = std::numeric_limits<double>::infinity();
    for (int y = std::max(0, v - 1); y <= std::min(past.rows - 1, v + 1); ++y) {
      const float* d = past.ptr<float>(y);
      for (int x = std::max(0, u - 1); x <= std::min(past.cols - 1, u + 1); ++x) {
        if (std::isfinite(d[x])) best = std::min(best, std::abs(double(d[x]) - r));
      }
    }
    if (!std::isfinite(best)) continue;  // no depth there: no evidence
    ++seen;
    agree += best <= tolerance;
  }
  if (seen < config_.min_points) return std::numeric_limits<double>::quiet_NaN();
  return double(agree) / seen;
}

std::vector<VehicleMotionTracker::Decision> VehicleMotionTracker::update(
    const std::vector<Detection>& boxes, int image_w, int image_h, const cv::Mat& depth, const CameraModel& camera,
    const std::optional<Eigen::Isometry3d>& T_W_C, double stamp_s) {
  if (!std::isfinite(stamp_s)) throw std::invalid_argument("vehicle motion: the stamp is not finite");
  if (image_w <= 0 || image_h <= 0)
    throw std::invalid_argument("vehicle motion: the detection image size must be positive, got " +
                                std::to_string(image_w) + " x " + std::to_string(image_h));
  if (depth.type() != CV_32FC1) throw std::invalid_argument("vehicle motion: depth must be 32FC1");
  if (depth.cols != camera.width() || depth.rows != camera.height())
    throw std::invalid_argument("vehicle motion: depth is " + std::to_string(depth.cols) + " x " +
                                std::to_string(depth.rows) + ", its camera " + std::to_string(camera.width()) +
                                " x " + std::to_string(camera.height()));
  if (stamp_s < last_stamp_) reset();  // time went backwards (a replayed bag)
  last_stamp_ = stamp_s;
  // Tracks unseen for too long are gone.
  tracks_.erase(std::remove_if(tracks_.begin(), tracks_.end(),
                               [&](const Track& t) { return stamp_s - t.last_seen > config_.max_gap; }),
                tracks_.end());
  ghosts_.erase(std::remove_if(ghosts_.begin(), ghosts_.end(), [&](const Ghost& g) { return stamp_s > g.until; }),
                ghosts_.end());
  std::vector<Decision> out(boxes.size());
  if (!T_W_C) return out;  // no pose: nothing can be placed
  // The static check's depth map: the newest at least static_interval old
  // (none when the newest kept is more than three intervals old).
  const Past* past = nullptr;
  const double dt = config_.static_interval;
  if (dt > 0.0) {
    while (past_.size() > 1 && stamp_s - past_[1].stamp >= dt) past_.pop_front();
    if (!past_.empty() && stamp_s - past_.front().stamp >= dt && stamp_s - past_.front().stamp <= 3.0 * dt)
      past = &past_.front();
  }
  std::vector<double> share(boxes.size(), std::numeric_limits<double>::quiet_NaN());
  std::vector<std::optional<Eigen::Vector3d>> pos(boxes.size());
  std::vector<char> cut(boxes.size(), 0);
  const double m = config_.border_px;
  std::vector<Eigen::Vector3d> body;
  for (size_t i = 0; i < boxes.size(); ++i) {
    pos[i] = place(boxes[i], image_w, image_h, depth, camera, *T_W_C, past ? &body : nullptr);
    if (past && pos[i] && (*pos[i] - T_W_C->translation()).norm() <= config_.static_range)
      share[i] = staticShare(body, *T_W_C, past->depth, camera, past->T_W_C);
    if (pos[i]) out[i].position = *pos[i];
    const Detection& b = boxes[i];
    cut[i] = b.x_min <= m || b.y_min <= m || b.x_max >= image_w - m || b.y_max >= image_h - m;
    // Too far to measure: tracked like a cut box.
    if (pos[i] && (*pos[i] - T_W_C->translation()).norm() > config_.decide_range) cut[i] = 1;
  }
  // Greedy association, nearest pairs first, within the gate around each
  // track's prediction (its last position moved on at its speed).
  std::vector<std::tuple<double, size_t, size_t>> pairs;  // (distance, box, track)
  for (size_t t = 0; t < tracks_.size(); ++t) {
    const Track& tr = tracks_[t];
    Eigen::Vector2d predicted = tr.last_position.head<2>();
    if (tr.history.size() >= 2) {
      const auto& a = tr.history.front();
      const auto& b = tr.history.back();
      if (b.first > a.first)
        predicted += (b.second - a.second).head<2>() / (b.first - a.first) * (stamp_s - tr.last_seen);
    }
    for (size_t i = 0; i < boxes.size(); ++i) {
      if (!pos[i]) continue;
      const double dist = (pos[i]->head<2>() - predicted).norm();
      if (dist <= config_.gate) pairs.emplace_back(dist, i, t);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<int> box_track(boxes.size(), -1);
  std::vector<char> track_used(tracks_.size(), 0);
  for (const auto& [dist, i, t] : pairs) {
    if (box_track[i] >= 0 || track_used[t]) continue;
    box_track[i] = static_cast<int>(t);
    track_used[t] = 1;
  }
  std::vector<size_t> unmatched;
  for (size_t i = 0; i < boxes.size(); ++i) {
    if (!pos[i]) continue;  // undecided: no position
    if (box_track[i] < 0) {
      unmatched.push_back(i);
      continue;
    }
    Track& tr = tracks_[box_track[i]];
    tr.last_seen = stamp_s;
    tr.last_position = *pos[i];
    out[i].track = tr.id;
    // A parked vehicle stays where it is: a box of its track placed farther
    // from where it stands than its scatter allows is another vehicle taken
    // for it (one driving past) or it drives off. Not fused as parked. (The
    // static check cannot overrule this: a truck overtaking close by, seen
    // by its flank, agrees with the depth map of 0.5 s before as a standing
    // body does.)
    const double noise_i = positionNoise(*pos[i], *T_W_C);
    const bool off_parked =
        !cut[i] && tr.state == VehicleMotion::Parked &&
        (pos[i]->head<2>() - tr.parked_position.head<2>()).norm() > config_.parked_tolerance + 2.0 * noise_i;
    if (!cut[i]) {
      tr.history.emplace_back(stamp_s, *pos[i]);
      tr.noise.push_back(noise_i);
      while (tr.history.size() > 2 && stamp_s - tr.history[1].first >= config_.speed_window) {
        tr.history.pop_front();
        tr.noise.pop_front();
      }
      const double speed = tr.speed();
      // Clear of the threshold by speed_significance standard errors.
      const double margin = config_.speed_significance > 0.0
                                ? config_.speed_significance * tr.speedError()
                                : 0.0;
      // The static check: measured now, counted in a row; it speaks only for
      // a vehicle whose measured velocity runs along the ego's heading.
      const bool still = std::isfinite(share[i]) && share[i] >= config_.static_share;
      if (std::isfinite(share[i])) tr.static_hits = still ? tr.static_hits + 1 : 0;
      if (std::isfinite(share[i])) tr.moved_hits = share[i] < config_.moving_share ? tr.moved_hits + 1 : 0;
      const bool along = alongHeading(tr, *T_W_C);
      const bool static_parked = along && tr.static_hits >= config_.static_frames;
      if (stamp_s - tr.first_seen + 1e-9 >= config_.decide_after && std::isfinite(speed) && std::isfinite(margin)) {
        // Called moving only where the static check (when on) finds the
        // body moved: at most moving_share of it agrees with the depth map
        // of static_interval before, in moving_frames measured frame sets in
        // a row (one it cannot measure neither counts nor breaks the row). A
        // vehicle it cannot measure (farther than static_range, no depth
        // there) stays undecided, so masked: a far parked car's placed
        // position slides with the coarse depth (it read 4-5 m/s 20-25 m
        // ahead), and a crossing one's flank fools it.
        const bool moved = config_.static_interval <= 0.0 || tr.moved_hits >= config_.moving_frames;
        if (speed - margin >= config_.moving_speed && moved) {
          if (tr.state == VehicleMotion::Parked && config_.carve_time > 0) {
            // Fused while parked, gone now: its region is carved.
            const Eigen::Vector3d h(config_.carve_half_size, config_.carve_half_size, 0.0);
            Ghost g;
            g.region = Eigen::AlignedBox3d(tr.parked_centre - h - Eigen::Vector3d(0, 0, 1.5),
                                           tr.parked_centre + h + Eigen::Vector3d(0, 0, 2.5));
            g.until = stamp_s + config_.carve_time;
            ghosts_.push_back(g);
          }
          tr.state = VehicleMotion::Moving;
        } else if (tr.state != VehicleMotion::Moving && (speed < config_.moving_speed || static_parked)) {
          if (speed + margin < config_.moving_speed || static_parked) tr.state = VehicleMotion::Parked;
          if (tr.state == VehicleMotion::Parked && !off_parked) {
            tr.parked_position = *pos[i];
            // The placed position is the face toward the camera along its
            // horizontal viewing direction: the body's middle lies half a
            // car's length (2.25 m) beyond it, which the carved region is
            // centred on.
            tr.parked_centre = *pos[i];
            if (const auto fwd = horizontalViewDirection(*T_W_C)) tr.parked_centre += 2.25 * *fwd;
          }
        }
      }
    }
    out[i].speed = tr.speed();
    out[i].motion = tr.state;  // a cut box keeps its track's decision
    if (off_parked && tr.state == VehicleMotion::Parked) out[i].motion = VehicleMotion::Undecided;
  }
  for (const size_t i : unmatched) {
    // A second box on a vehicle tracked in this frame set: its decision.
    int same = -1;
    double best = config_.duplicate_distance;
    for (size_t j = 0; j < boxes.size(); ++j) {
      if (j == i || out[j].track < 0) continue;  // tracked now (matched or new)
      const double dist = (pos[i]->head<2>() - pos[j]->head<2>()).norm();
      if (dist <= best) best = dist, same = static_cast<int>(j);
    }
    if (same >= 0) {
      out[i].track = out[same].track;
      out[i].speed = out[same].speed;
      out[i].motion = out[same].motion;
      continue;
    }
    Track tr;
    tr.id = next_id_++;
    tr.first_seen = tr.last_seen = stamp_s;
    tr.last_position = *pos[i];
    if (!cut[i]) {
      tr.history.emplace_back(stamp_s, *pos[i]);
      tr.noise.push_back(positionNoise(*pos[i], *T_W_C));
    }
    tracks_.push_back(std::move(tr));
    out[i].track = tracks_.back().id;  // undecided: new
  }
  if (dt > 0.0) past_.push_back({stamp_s, depth.clone(), *T_W_C});
  return out;
}

}  // namespace fisheye_mapping

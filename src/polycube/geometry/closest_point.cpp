#include "polycube/geometry/closest_point.h"

#include <algorithm>
#include <limits>

namespace polycube::geometry {

double closest_point_on_segment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double l2 = ab.squaredNorm();
  return l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
}

Vec3 closest_point_barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  // Voronoi regions of the triangle (Ericson, Real-Time Collision Detection, 5.1.5).
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0)) return {1, 0, 0};  // degenerate triangle
  const double v = vb / denom, w = vc / denom;
  return {1 - v - w, v, w};
}

TriangleTree::TriangleTree(const MatX3d& V, const MatX3i& F) : V_(V), F_(F), order_(F.rows()) {
  for (int i = 0; i < F.rows(); ++i) order_[i] = i;
  nodes_.reserve(2 * F.rows() / 4 + 2);
  if (F.rows() > 0) build(0, static_cast<int>(F.rows()));
  tris_.resize(order_.size());
  for (size_t i = 0; i < order_.size(); ++i) {
    Tri& t = tris_[i];
    const int f = order_[i];
    t.a = V_.row(F_(f, 0));
    t.b = V_.row(F_(f, 1));
    t.c = V_.row(F_(f, 2));
    t.cross = (t.b - t.a).cross(t.c - t.a);
    const double l = t.cross.norm();
    // Slivers (sine of the smallest angle under 1e-4) get no plane bound: their normal's rounding.
    const double e = std::max({(t.b - t.a).squaredNorm(), (t.c - t.a).squaredNorm(), (t.c - t.b).squaredNorm()});
    t.unit = l > 1e-4 * e ? Vec3(t.cross / l) : Vec3::Zero();
    t.offset = t.unit.dot(t.a);
  }
}

int TriangleTree::build(int begin, int end) {
  const int id = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Eigen::AlignedBox3d box;
  for (int i = begin; i < end; ++i)
    for (int k = 0; k < 3; ++k) box.extend(Vec3(V_.row(F_(order_[i], k))));
  nodes_[id].box = box;
  if (end - begin <= 4) {
    nodes_[id].begin = begin;
    nodes_[id].end = end;
    return id;
  }
  int axis;
  box.sizes().maxCoeff(&axis);
  auto centroid = [&](int f) { return V_(F_(f, 0), axis) + V_(F_(f, 1), axis) + V_(F_(f, 2), axis); };
  const int mid = (begin + end) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int a, int b) { return centroid(a) < centroid(b); });
  const int l = build(begin, mid);
  const int r = build(mid, end);
  nodes_[id].left = l;
  nodes_[id].right = r;
  return id;
}

ClosestHit TriangleTree::closest(const Vec3& p, const Vec3* facing, const std::vector<int>* group, int group_id) const {
  ClosestHit best;
  best.dist2 = std::numeric_limits<double>::infinity();
  if (nodes_.empty()) return best;
  // Depth-first; the tree splits at the median, so it is at most ~log2(faces) deep and the stack
  // holds at most one node per level plus one (no allocation per query).
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    if (n.box.squaredExteriorDistance(p) >= best.dist2) continue;
    if (n.left < 0) {
      for (int i = n.begin; i < n.end; ++i) {
        const int f = order_[i];
        const Tri& t = tris_[i];
        if (facing && !(t.cross.dot(*facing) > 0)) continue;
        if (group && (*group)[f] != group_id) continue;
        // The distance to the triangle's plane bounds the distance to it from below. Margins over
        // the rounding (the cancellation in h is relative to the coordinates' size) so that only
        // triangles whose computed distance could not be the smaller are skipped.
        const double up = t.unit.dot(p), h = std::abs(up - t.offset) - 1e-12 * (std::abs(up) + std::abs(t.offset));
        if (h > 0 && h * h > best.dist2 * (1 + 1e-6)) continue;
        const Vec3 w = closest_point_barycentric(p, t.a, t.b, t.c);
        const Vec3 q = w[0] * t.a + w[1] * t.b + w[2] * t.c;
        const double d2 = (q - p).squaredNorm();
        if (d2 < best.dist2) best = {f, w, q, d2};
      }
      continue;
    }
    // Nearer child last, so that it is popped first.
    const double dl = nodes_[n.left].box.squaredExteriorDistance(p), dr = nodes_[n.right].box.squaredExteriorDistance(p);
    if (dl < dr) {
      stack[top++] = n.right;
      stack[top++] = n.left;
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  if (group && best.face < 0) return closest(p, facing);  // no triangle of that group
  if (facing && best.face < 0) return closest(p);         // no triangle faces that way
  return best;
}

}  // namespace polycube::geometry

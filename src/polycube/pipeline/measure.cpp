#include "polycube/pipeline/measure.h"

#include <algorithm>
#include <vector>

#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/hex/quality.h"
#include "polycube/io/readers.h"
#include "polycube/quad/quad.h"
#include "polycube/validate/tetmesh.h"

namespace polycube {

namespace {

// The surface of a mesh file: its triangles (and quads), or the boundary of its volume cells.
SurfaceMesh surface_of(const MeshData& m) {
  SurfaceMesh s;
  s.V = m.V;
  if (m.H.rows() > 0) {
    s.F = hex::triangulate_quads(hex::boundary_quads(m.H));  // the hex mesh's boundary
  } else if (m.T.rows() > 0) {
    s.F = tet_boundary(m.T, m.path);
  } else {
    const MatX3i FQ = hex::triangulate_quads(m.Q);
    s.F.resize(m.F.rows() + FQ.rows(), 3);
    s.F << m.F, FQ;
  }
  return s;
}

// Quads of a surface file whose polygons were triangulated on reading (OBJ, OFF, PLY): every file
// face must have given two triangles sharing a diagonal, (u, v, p) and (v, u, r): the quad u r v p,
// started at the polygon's first vertex (the first of its first triangle).
// Any other face makes the file no quad mesh; the first is named.
MatX4i quads_of_polygons(const MeshData& m) {
  const int nf = static_cast<int>(m.F.rows());
  int faces = 0;
  for (int f = 0; f < nf; ++f) faces = std::max(faces, m.face_source[f] + 1);
  std::vector<std::vector<int>> tris(faces);
  for (int f = 0; f < nf; ++f) tris[m.face_source[f]].push_back(f);
  MatX4i Q(faces, 4);
  for (int s = 0; s < faces; ++s) {
    const auto& t = tris[s];
    bool found = false;
    for (int i = 0; t.size() == 2 && i < 3 && !found; ++i) {
      const int u = m.F(t[0], i), v = m.F(t[0], (i + 1) % 3), p = m.F(t[0], (i + 2) % 3);
      for (int k = 0; k < 3 && !found; ++k)
        if (m.F(t[1], k) == v && m.F(t[1], (k + 1) % 3) == u) {
          const int c[4] = {u, m.F(t[1], (k + 2) % 3), v, p};
          int r = 0;  // the polygon's first vertex starts its first triangle (io::triangulate_polygon)
          while (c[r] != m.F(t[0], 0)) ++r;
          for (int j = 0; j < 4; ++j) Q(s, j) = c[(r + j) % 4];
          found = true;
        }
    }
    if (!found)
      throw Error(ErrorKind::InvalidMesh, m.path + ": not a quad mesh: " +
                                              (t.empty() ? "face " + std::to_string(s + 1) : m.face_where(t[0])) +
                                              " is not a quadrilateral (" + std::to_string(t.size()) +
                                              " triangles on reading; measure takes hexahedra or quadrilaterals)");
  }
  return Q;
}

}  // namespace

nlohmann::json edge_ratio_json(const hex::QualityStats& q) {
  return {{"max", q.edge_ratio_max},
          {"mean", q.edge_ratio_mean},
          {"above_10", q.edge_ratio_above_10},
          {"above_100", q.edge_ratio_above_100}};
}

void add_hausdorff(nlohmann::json& j, const hex::Hausdorff& d, double diag, const std::string& key) {
  auto point = [](const Vec3& p) { return nlohmann::json::array({p.x(), p.y(), p.z()}); };
  j["hausdorff"] = d.max;
  j["hausdorff_rel"] = d.max / diag;
  j["hausdorff_" + key + "_to_input"] = d.a_to_b;
  j["hausdorff_input_to_" + key] = d.b_to_a;
  j["hausdorff_" + key + "_to_input_at"] = point(d.a_to_b_at);
  j["hausdorff_input_to_" + key + "_at"] = point(d.b_to_a_at);
  j["mean_distance_rel"] = d.mean() / diag;
  j["rms_distance_rel"] = d.rms() / diag;
  // Per side, like Metro / M.E.S.H. / MeshLab (max, mean, RMS, relative to the bbox diagonal).
  auto side = [&](double mx, double mean, double rms) {
    return nlohmann::json{{"max_rel", mx / diag}, {"mean_rel", mean / diag}, {"rms_rel", rms / diag}};
  };
  j["distance"] = {{key + "_to_input", side(d.a_to_b, d.mean_a_to_b, d.rms_a_to_b)},
                   {"input_to_" + key, side(d.b_to_a, d.mean_b_to_a, d.rms_b_to_a)}};
}

nlohmann::json measure_mesh(const MeasureOptions& opt, const Hooks& hooks) {
  Stopwatch sw;
  hooks.info("reading " + opt.path);
  MeshData m = io::read_mesh(opt.path, {}, true);
  // Surface formats store quads as polygons, triangulated on reading: take them back.
  const bool polygon_file = m.format == "obj" || m.format == "off" || m.format.rfind("ply", 0) == 0;
  if (m.H.rows() == 0 && m.Q.rows() == 0 && m.T.rows() == 0 && polygon_file && m.F.rows() > 1 &&
      !m.face_source.empty() && m.face_source[0] == m.face_source[1]) {
    m.Q = quads_of_polygons(m);
    m.F.resize(0, 3);
  }
  if (m.H.rows() == 0 && m.Q.rows() == 0)
    throw Error(ErrorKind::InvalidMesh, opt.path + ": no hexahedra or quadrilaterals to measure");
  const bool quads = m.H.rows() == 0;
  for (int h = 0; h < m.H.rows(); ++h)
    for (int i = 0; i < 8; ++i)
      for (int j = i + 1; j < 8; ++j)
        if (m.H(h, i) == m.H(h, j))
          throw Error(ErrorKind::InvalidMesh, opt.path + ": hex " + std::to_string(h + 1) + " repeats vertex " +
                                                  std::to_string(m.H(h, i) + 1));
  nlohmann::json j;
  j["input"] = {{"path", opt.path}, {"format", m.format}, {"vertices", m.V.rows()}};
  const char* key = quads ? "quad" : "hex";
  if (quads) {
    const quad::QuadQuality q = quad::quad_quality(m.V, m.Q);
    nlohmann::json hist = nlohmann::json::array();
    for (int c : q.histogram) hist.push_back(c);
    j[key] = {{"count", q.count},       {"sj_min", q.sj_min},         {"sj_mean", q.sj_mean},
              {"sj_max", q.sj_max},     {"inverted", q.inverted},     {"below_0_5", q.below_0_5},
              {"sj_histogram", hist},   {"edge_ratio", edge_ratio_json(q)}};
  } else {
    const hex::HexQuality q = hex::hex_quality(m.V, m.H);
    nlohmann::json hist = nlohmann::json::array();
    for (int c : q.histogram) hist.push_back(c);
    j[key] = {{"count", q.count},         {"sj_min", q.sj_min},         {"sj_mean", q.sj_mean},
              {"sj_max", q.sj_max},       {"inverted", q.inverted},     {"below_0_2", q.below_0_2},
              {"below_0_5", q.below_0_5}, {"sj_histogram", hist},         {"edge_ratio", edge_ratio_json(q)}};
  }
  if (!opt.reference.empty()) {
    hooks.info("reading reference " + opt.reference);
    const MeshData r = io::read_mesh(opt.reference);
    const SurfaceMesh rs = surface_of(r), hs = surface_of(m);
    if (rs.F.rows() == 0) throw Error(ErrorKind::InvalidMesh, opt.reference + ": no surface to compare with");
    const hex::Hausdorff d = hex::hausdorff(hs.V, hs.F, rs.V, rs.F, opt.samples);
    Eigen::AlignedBox3d box;
    for (int f = 0; f < rs.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) box.extend(rs.V.row(rs.F(f, k)).transpose());
    const double diag = box.diagonal().norm();
    j["reference"] = {{"path", opt.reference}, {"bbox_diagonal", diag}};
    add_hausdorff(j[key], d, diag, key);
    // Hexes of a closed reference: how much of their volume lies outside it (gaps filled).
    if (!quads && border_loops(rs.F).empty())
      j[key]["volume_outside_rel"] = hex::volume_outside(m.V, m.H, rs.V, rs.F);
  }
  j["seconds"] = sw.seconds();
  return j;
}

}  // namespace polycube

// Readers of surface formats: OBJ, OFF, STL (ASCII/binary), PLY (ASCII/binary LE/BE).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <unordered_map>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/readers.h"
#include "polycube/io/text_reader.h"

namespace polycube::io {

static std::string str(std::string_view s) { return std::string(s); }

// ---------------------------------------------------------------- OBJ
MeshData read_obj(const std::string& path) {
  std::string data = read_file(path);
  TextReader r(data, path, '#');
  Builder b;
  std::vector<std::string_view> tok;
  std::vector<int> poly;
  std::string_view line;
  int nface = 0;
  std::string group;                    // current `g` / `o` name
  std::vector<std::string> face_groups; // per file face
  bool any_group = false;
  while (r.next_line(line)) {
    split(line, tok);
    if (tok.empty()) continue;
    if (tok[0] == "g" || tok[0] == "o") {
      group.clear();
      for (size_t k = 1; k < tok.size(); ++k) group += (k > 1 ? " " : "") + str(tok[k]);
      any_group = any_group || !group.empty();
    } else if (tok[0] == "v") {
      if (tok.size() < 4) r.fail("vertex needs 3 coordinates, found " + std::to_string(tok.size() - 1));
      double x[3];
      for (int k = 0; k < 3; ++k)
        if (!parse_double(tok[k + 1], x[k])) r.fail("expected a number for vertex coordinate, found '" + str(tok[k + 1]) + "'");
      b.add_vertex(x[0], x[1], x[2], r.line());
    } else if (tok[0] == "f" || tok[0] == "fo") {
      if (tok.size() < 4) r.fail("face needs at least 3 vertices, found " + std::to_string(tok.size() - 1));
      poly.clear();
      for (size_t k = 1; k < tok.size(); ++k) {
        std::string_view t = tok[k].substr(0, tok[k].find('/'));  // v/vt/vn: keep v
        long long idx;
        if (!parse_int(t, idx)) r.fail("expected a vertex index in face, found '" + str(tok[k]) + "'");
        const long long n = b.num_vertices();
        long long i0 = idx > 0 ? idx - 1 : n + idx;  // negative = relative to the last vertex
        if (idx == 0 || i0 < 0 || i0 >= n)
          r.fail("face vertex index " + std::to_string(idx) + " out of range (" + std::to_string(n) +
                 " vertices defined so far)");
        poly.push_back(static_cast<int>(i0));
      }
      b.add_polygon(poly, nface++, r.line());
      face_groups.push_back(group);
    }
    // vt, vn, vp, s, usemtl, mtllib, l, p: not geometry we use.
  }
  MeshData m;
  m.path = path;
  m.format = "obj";
  b.finish(m);
  if (any_group) {
    m.face_group.resize(m.F.rows());
    for (int f = 0; f < m.F.rows(); ++f) m.face_group[f] = face_groups[m.face_source[f]];
  }
  return m;
}

// ---------------------------------------------------------------- OFF
MeshData read_off(const std::string& path) {
  std::string data = read_file(path);
  TextReader r(data, path, '#');
  std::string_view line;
  std::vector<std::string_view> tok;
  if (!r.next_line(line)) r.fail("empty OFF file");
  split(line, tok);
  size_t first = 0;
  if (tok[0].size() >= 3 && tok[0].substr(tok[0].size() - 3) == "OFF") {
    if (tok[0] != "OFF" && tok[0] != "COFF" && tok[0] != "NOFF" && tok[0] != "CNOFF" && tok[0] != "STOFF")
      r.fail("unsupported OFF variant '" + str(tok[0]) + "'");
    first = 1;
  } else {
    r.fail("not an OFF file: first line must be 'OFF', found '" + str(line) + "'");
  }
  if (tok.size() == first) {
    if (!r.next_line(line)) r.fail("missing vertex/face counts (file truncated?)");
    split(line, tok);
    first = 0;
  }
  long long nv, nf;
  if (tok.size() < first + 2 || !parse_int(tok[first], nv) || !parse_int(tok[first + 1], nf) || nv < 0 || nf < 0)
    r.fail("expected 'nvertices nfaces nedges', found '" + str(line) + "'");
  Builder b;
  for (long long i = 0; i < nv; ++i) {
    if (!r.next_line(line))
      r.fail("file ends after " + std::to_string(i) + " of " + std::to_string(nv) + " vertices (truncated?)");
    split(line, tok);
    double x[3];
    if (tok.size() < 3) r.fail("vertex needs 3 coordinates");
    for (int k = 0; k < 3; ++k)
      if (!parse_double(tok[k], x[k])) r.fail("expected a number for vertex coordinate, found '" + str(tok[k]) + "'");
    b.add_vertex(x[0], x[1], x[2], r.line());
  }
  std::vector<int> poly;
  for (long long i = 0; i < nf; ++i) {
    if (!r.next_line(line))
      r.fail("file ends after " + std::to_string(i) + " of " + std::to_string(nf) + " faces (truncated?)");
    split(line, tok);
    long long k;
    if (tok.empty() || !parse_int(tok[0], k) || k < 3)
      r.fail("face must start with its vertex count (>= 3), found '" + str(line) + "'");
    if (static_cast<long long>(tok.size()) < k + 1)
      r.fail("face announces " + std::to_string(k) + " vertices but lists " + std::to_string(tok.size() - 1));
    poly.clear();
    for (long long j = 0; j < k; ++j) {
      long long idx;
      if (!parse_int(tok[j + 1], idx)) r.fail("expected a vertex index, found '" + str(tok[j + 1]) + "'");
      if (idx < 0 || idx >= nv)
        r.fail("face vertex index " + std::to_string(idx) + " out of range [0, " + std::to_string(nv) + ")");
      poly.push_back(static_cast<int>(idx));
    }
    b.add_polygon(poly, static_cast<int>(i), r.line());
  }
  MeshData m;
  m.path = path;
  m.format = "off";
  b.finish(m);
  return m;
}

// ---------------------------------------------------------------- STL
namespace {
struct KeyHash {
  size_t operator()(const std::array<double, 3>& k) const {
    size_t h = 1469598103934665603ull;
    for (double d : k) {
      uint64_t u;
      std::memcpy(&u, &d, 8);
      h = (h ^ u) * 1099511628211ull;
    }
    return h;
  }
};
// Welds exactly coincident points: STL repeats every vertex per facet.
struct Welder {
  std::unordered_map<std::array<double, 3>, int, KeyHash> map;
  Builder& b;
  int seen = 0;
  explicit Welder(Builder& bb) : b(bb) {}
  int add(double x, double y, double z, int line) {
    ++seen;
    std::array<double, 3> k{x + 0.0, y + 0.0, z + 0.0};  // +0.0 folds -0 into 0
    auto it = map.find(k);
    if (it != map.end()) return it->second;
    int id = b.num_vertices();
    b.add_vertex(x, y, z, line);
    map.emplace(k, id);
    return id;
  }
};
}  // namespace

static MeshData read_stl_binary(const std::string& path, const std::string& data) {
  if (data.size() < 84) throw Error(ErrorKind::Parse, path + ": binary STL shorter than its 84-byte header (truncated?)");
  uint32_t n;
  std::memcpy(&n, data.data() + 80, 4);
  const size_t need = 84 + size_t(n) * 50;
  if (data.size() < need)
    throw Error(ErrorKind::Parse, path + ": binary STL announces " + std::to_string(n) + " facets (" +
                                      std::to_string(need) + " bytes) but has " + std::to_string(data.size()) +
                                      " bytes: truncated after facet " + std::to_string((data.size() - 84) / 50));
  Builder b;
  Welder w(b);
  for (uint32_t i = 0; i < n; ++i) {
    const char* p = data.data() + 84 + size_t(i) * 50 + 12;
    int id[3];
    for (int k = 0; k < 3; ++k) {
      float c[3];
      std::memcpy(c, p + 12 * k, 12);
      id[k] = w.add(c[0], c[1], c[2], 0);
    }
    b.add_triangle(id[0], id[1], id[2], static_cast<int>(i), 0);
  }
  MeshData m;
  m.path = path;
  m.format = "stl-binary";
  b.finish(m);
  m.welded_vertices = w.seen - b.num_vertices();
  return m;
}

static MeshData read_stl_ascii(const std::string& path, const std::string& data) {
  TextReader r(data, path, 0);
  Builder b;
  Welder w(b);
  std::string_view t = r.expect("'solid'");
  if (t != "solid") r.fail("ASCII STL must start with 'solid'");
  // The name after 'solid' runs to the end of the line.
  std::string_view line;
  r.next_line(line);
  int nf = 0;
  for (;;) {
    std::string_view k;
    if (!r.next(k)) r.fail("missing 'endsolid' (file truncated?)");
    if (k == "endsolid") break;
    if (k != "facet") r.fail("expected 'facet' or 'endsolid', found '" + str(k) + "'");
    if (r.expect("'normal'") != "normal") r.fail("expected 'normal' after 'facet'");
    for (int i = 0; i < 3; ++i) r.read_double("facet normal");
    if (r.expect("'outer'") != "outer" || r.expect("'loop'") != "loop") r.fail("expected 'outer loop'");
    int id[3];
    int fl = 0;
    for (int i = 0; i < 3; ++i) {
      if (r.expect("'vertex'") != "vertex") r.fail("expected 'vertex' (STL facets must be triangles)");
      if (i == 0) fl = r.line();
      double x = r.read_double("vertex x"), y = r.read_double("vertex y"), z = r.read_double("vertex z");
      id[i] = w.add(x, y, z, r.line());
    }
    if (r.expect("'endloop'") != "endloop") r.fail("expected 'endloop' (STL facets must be triangles)");
    if (r.expect("'endfacet'") != "endfacet") r.fail("expected 'endfacet'");
    b.add_triangle(id[0], id[1], id[2], nf++, fl);
  }
  MeshData m;
  m.path = path;
  m.format = "stl-ascii";
  b.finish(m);
  m.welded_vertices = w.seen - b.num_vertices();
  return m;
}

MeshData read_stl(const std::string& path) {
  std::string data = read_file(path);
  // Binary files may also start with "solid": decide by the announced size first.
  if (data.size() >= 84) {
    uint32_t n;
    std::memcpy(&n, data.data() + 80, 4);
    if (84 + size_t(n) * 50 == data.size()) return read_stl_binary(path, data);
  }
  size_t s = data.find_first_not_of(" \t\r\n");
  if (s != std::string::npos && data.compare(s, 5, "solid") == 0 &&
      data.find("facet", s) != std::string::npos)
    return read_stl_ascii(path, data);
  if (s != std::string::npos && data.compare(s, 5, "solid") == 0 && data.find('\0') == std::string::npos)
    return read_stl_ascii(path, data);
  return read_stl_binary(path, data);
}

// ---------------------------------------------------------------- PLY
namespace {
enum class PlyType { I8, U8, I16, U16, I32, U32, F32, F64 };
bool ply_type(std::string_view s, PlyType& t) {
  if (s == "char" || s == "int8") t = PlyType::I8;
  else if (s == "uchar" || s == "uint8") t = PlyType::U8;
  else if (s == "short" || s == "int16") t = PlyType::I16;
  else if (s == "ushort" || s == "uint16") t = PlyType::U16;
  else if (s == "int" || s == "int32") t = PlyType::I32;
  else if (s == "uint" || s == "uint32") t = PlyType::U32;
  else if (s == "float" || s == "float32") t = PlyType::F32;
  else if (s == "double" || s == "float64") t = PlyType::F64;
  else return false;
  return true;
}
int ply_size(PlyType t) {
  switch (t) {
    case PlyType::I8: case PlyType::U8: return 1;
    case PlyType::I16: case PlyType::U16: return 2;
    case PlyType::I32: case PlyType::U32: case PlyType::F32: return 4;
    case PlyType::F64: return 8;
  }
  return 1;
}
struct PlyProp {
  std::string name;
  bool list = false;
  PlyType count_type = PlyType::U8, type = PlyType::F32;
};
struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProp> props;
};
struct BinCursor {
  const std::string& d;
  size_t pos;
  bool big;
  const std::string& path;
  std::string what;
  double read(PlyType t) {
    int s = ply_size(t);
    if (pos + s > d.size()) throw Error(ErrorKind::Parse, path + ": binary data ends inside " + what + " (truncated?)");
    unsigned char b[8];
    std::memcpy(b, d.data() + pos, s);
    pos += s;
    if (big) std::reverse(b, b + s);
    switch (t) {
      case PlyType::I8: return static_cast<int8_t>(b[0]);
      case PlyType::U8: return b[0];
      case PlyType::I16: { int16_t v; std::memcpy(&v, b, 2); return v; }
      case PlyType::U16: { uint16_t v; std::memcpy(&v, b, 2); return v; }
      case PlyType::I32: { int32_t v; std::memcpy(&v, b, 4); return v; }
      case PlyType::U32: { uint32_t v; std::memcpy(&v, b, 4); return v; }
      case PlyType::F32: { float v; std::memcpy(&v, b, 4); return v; }
      case PlyType::F64: { double v; std::memcpy(&v, b, 8); return v; }
    }
    return 0;
  }
};
}  // namespace

MeshData read_ply(const std::string& path) {
  std::string data = read_file(path);
  if (data.compare(0, 3, "ply") != 0) throw Error(ErrorKind::Parse, path + ":1: not a PLY file (must start with 'ply')");
  size_t he = data.find("end_header");
  if (he == std::string::npos) throw Error(ErrorKind::Parse, path + ": PLY header has no 'end_header' (truncated?)");
  size_t body = data.find('\n', he);
  body = body == std::string::npos ? data.size() : body + 1;
  TextReader h(std::string_view(data).substr(0, body), path, 0);
  std::string_view line;
  std::vector<std::string_view> tok;
  std::vector<PlyElement> elems;
  std::string format;
  h.next_line(line);  // "ply"
  while (h.next_line(line)) {
    split(line, tok);
    if (tok[0] == "format") {
      if (tok.size() < 2) h.fail("incomplete 'format' line");
      format = str(tok[1]);
      if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
        h.fail("unknown PLY format '" + format + "'");
    } else if (tok[0] == "element") {
      long long c;
      if (tok.size() < 3 || !parse_int(tok[2], c) || c < 0) h.fail("malformed 'element' line");
      elems.push_back({str(tok[1]), c, {}});
    } else if (tok[0] == "property") {
      if (elems.empty()) h.fail("'property' before any 'element'");
      PlyProp p;
      if (tok.size() >= 5 && tok[1] == "list") {
        p.list = true;
        if (!ply_type(tok[2], p.count_type) || !ply_type(tok[3], p.type)) h.fail("unknown PLY property type");
        p.name = str(tok[4]);
      } else if (tok.size() >= 3) {
        if (!ply_type(tok[1], p.type)) h.fail("unknown PLY property type '" + str(tok[1]) + "'");
        p.name = str(tok[2]);
      } else {
        h.fail("malformed 'property' line");
      }
      elems.back().props.push_back(p);
    } else if (tok[0] == "end_header") {
      break;
    }  // comment, obj_info: ignored
  }
  if (format.empty()) h.fail("PLY header has no 'format' line");
  Builder b;
  long long nv = -1;
  const bool ascii = format == "ascii";
  TextReader ar(data, path, 0);
  // Position the ASCII reader after the header, keeping line numbers.
  if (ascii) {
    std::string_view l;
    while (ar.next_line(l)) if (l.substr(0, 10) == "end_header") break;
  }
  BinCursor bc{data, body, format == "binary_big_endian", path, ""};
  std::vector<int> poly;
  int fcount = 0;
  std::vector<std::string> ply_groups;  // per file face, when a region property exists
  for (const PlyElement& e : elems) {
    const bool is_v = e.name == "vertex", is_f = e.name == "face";
    int ix = -1, iy = -1, iz = -1, ifc = -1, ireg = -1;
    for (size_t k = 0; k < e.props.size(); ++k) {
      if (!e.props[k].list && (e.props[k].name == "region" || e.props[k].name == "group" ||
                               e.props[k].name == "label" || e.props[k].name == "segment"))
        ireg = static_cast<int>(k);
      if (e.props[k].name == "x") ix = static_cast<int>(k);
      if (e.props[k].name == "y") iy = static_cast<int>(k);
      if (e.props[k].name == "z") iz = static_cast<int>(k);
      if (e.props[k].list && (e.props[k].name == "vertex_indices" || e.props[k].name == "vertex_index")) ifc = static_cast<int>(k);
    }
    if (is_v && (ix < 0 || iy < 0 || iz < 0)) throw Error(ErrorKind::Parse, path + ": PLY vertex element lacks x, y or z");
    if (is_f && ifc < 0) throw Error(ErrorKind::Parse, path + ": PLY face element lacks a 'vertex_indices' list");
    if (is_f && nv < 0) throw Error(ErrorKind::Parse, path + ": PLY face element before vertex element");
    if (is_v) nv = e.count;
    for (long long i = 0; i < e.count; ++i) {
      double xyz[3] = {0, 0, 0};
      double region = 0;
      poly.clear();
      int line = 0;
      bc.what = e.name + " " + std::to_string(i);
      for (size_t k = 0; k < e.props.size(); ++k) {
        const PlyProp& p = e.props[k];
        auto read_one = [&](PlyType t, const char* what) -> double {
          if (!ascii) return bc.read(t);
          double v = ar.read_double(what);
          if (line == 0) line = ar.line();
          return v;
        };
        if (p.list) {
          double c = read_one(p.count_type, "list count");
          if (c < 0 || c != std::floor(c)) throw Error(ErrorKind::Parse, path + ": bad list count in " + e.name + " " + std::to_string(i));
          for (int j = 0; j < static_cast<int>(c); ++j) {
            double v = read_one(p.type, "face vertex index");
            if (is_f && static_cast<int>(k) == ifc) {
              if (v < 0 || v >= nv || v != std::floor(v))
                throw Error(ErrorKind::Parse, path + (line ? ":" + std::to_string(line) : std::string()) + ": face " +
                                                  std::to_string(i) + " vertex index " + std::to_string(static_cast<long long>(v)) +
                                                  " out of range [0, " + std::to_string(nv) + ")");
              poly.push_back(static_cast<int>(v));
            }
          }
        } else {
          double v = read_one(p.type, "property value");
          if (static_cast<int>(k) == ix) xyz[0] = v;
          if (static_cast<int>(k) == iy) xyz[1] = v;
          if (static_cast<int>(k) == iz) xyz[2] = v;
          if (static_cast<int>(k) == ireg) region = v;
        }
      }
      if (is_v) b.add_vertex(xyz[0], xyz[1], xyz[2], line);
      if (is_f) {
        if (poly.size() < 3)
          throw Error(ErrorKind::Parse, path + (line ? ":" + std::to_string(line) : std::string()) + ": face " +
                                            std::to_string(i) + " has " + std::to_string(poly.size()) + " vertices (needs >= 3)");
        b.add_polygon(poly, fcount++, line);
        if (ireg >= 0) {
          std::ostringstream name;
          name << region;
          ply_groups.push_back(name.str());
        }
      }
    }
  }
  MeshData m;
  m.path = path;
  m.format = "ply-" + std::string(ascii ? "ascii" : format == "binary_big_endian" ? "binary-be" : "binary-le");
  b.finish(m);
  if (!ply_groups.empty()) {
    m.face_group.resize(m.F.rows());
    for (int f = 0; f < m.F.rows(); ++f) m.face_group[f] = ply_groups[m.face_source[f]];
  }
  return m;
}

}  // namespace polycube::io

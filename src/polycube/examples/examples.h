// Built-in example shapes, modelled with Gmsh's OpenCASCADE kernel and meshed with triangles,
// so that the tool runs without any input file.
#pragma once
#include <string>
#include <vector>

#include "polycube/io/mesh_data.h"

namespace polycube::examples {

struct ExampleInfo {
  std::string name;
  std::string description;
};

/// Every built-in example, in a fixed order.
const std::vector<ExampleInfo>& list();

/// Builds the named example as a closed triangle surface (format "example:NAME"), with target
/// edge length `mesh_size` relative to its bounding-box diagonal. Throws Error(Usage) for an
/// unknown name (the message lists the known ones).
MeshData make(const std::string& name, double mesh_size = 0.04);

}  // namespace polycube::examples

#include "polycube/core/error.h"

namespace polycube {

const char* to_string(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::Usage: return "usage";
    case ErrorKind::Parse: return "parse";
    case ErrorKind::InvalidMesh: return "invalid_mesh";
    case ErrorKind::Tetrahedralization: return "tetrahedralization";
    case ErrorKind::Output: return "output";
    case ErrorKind::Polycube: return "polycube";
    case ErrorKind::Internal: return "internal";
  }
  return "internal";
}

int exit_code(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::Usage: return 2;
    case ErrorKind::Parse: return 3;
    case ErrorKind::InvalidMesh: return 4;
    case ErrorKind::Tetrahedralization: return 5;
    case ErrorKind::Output: return 6;
    case ErrorKind::Polycube: return 7;
    case ErrorKind::Internal: return 70;
  }
  return 70;
}

}  // namespace polycube

// Errors the library reports. Expected failures (bad input, a mesher that gives up, an output that
// cannot be written) are thrown as polycube::Error with a kind and a message that names the problem
// and where it is (file, line, element or vertex ids). The CLI maps the kind to an exit code.
#pragma once
#include <stdexcept>
#include <string>

namespace polycube {

enum class ErrorKind {
  Usage,              ///< bad option or argument
  Parse,              ///< unreadable, empty, truncated or malformed file
  InvalidMesh,        ///< readable but unusable: non-manifold, open, degenerate, self-intersecting...
  Tetrahedralization, ///< the tet mesher failed or produced an invalid mesh
  Output,             ///< an output file could not be written
  Polycube,           ///< no valid polycube could be built from the deformation
  Internal,           ///< a broken invariant: a bug
};

class Error : public std::runtime_error {
 public:
  Error(ErrorKind kind, const std::string& message) : std::runtime_error(message), kind_(kind) {}
  ErrorKind kind() const { return kind_; }

 private:
  ErrorKind kind_;
};

/// Short name of an error kind ("parse", "invalid_mesh", ...), used in report.json.
const char* to_string(ErrorKind kind);

/// Process exit code of the CLI for an error kind (documented in README.md).
int exit_code(ErrorKind kind);

/// Throws Error(Internal) when `cond` is false. Stays on in release builds.
#define POLYCUBE_ASSERT(cond, msg)                                                        \
  do {                                                                                    \
    if (!(cond))                                                                          \
      throw ::polycube::Error(::polycube::ErrorKind::Internal,                            \
                              std::string("internal error: ") + (msg) + " (" #cond ", " + \
                                  __FILE__ + ":" + std::to_string(__LINE__) + ")");       \
  } while (0)

}  // namespace polycube

/// @file edit_file.h
/// @brief Edit files: JSON scripts of constraint edits (schema in README.md, "Edit files").
///
/// {"lattice": {"size": 9 | [nx, ny, nz], "placement": "uniform" | "clamped", "padding": 0.25},   (all optional)
///  "edits": [ {"constraints": [ {"move": [x,y,z], "to": [x,y,z], "weight": w},
///                               {"pin": [x,y,z], "weight": w},
///                               {"control_point": [i,j,k], "offset": [dx,dy,dz], "weight": w} ],
///              "solver": "min-norm" | "rigid", "preserve_volume": false} ]}      (solver, preserve_volume optional)
/// Points are world coordinates. Validation is strict: unknown or missing fields, wrong types, non-finite
/// numbers and out-of-range values are refused with the file, the JSON path and what was expected.
#pragma once

#include <voxwarp/constraints.h>
#include <voxwarp/warp.h>

#include <string>
#include <vector>

namespace voxwarp {

/// How an edit's constraints are turned into lattice motion.
enum class Solver {
    min_norm, ///< the least control-point motion (Hsu, Hughes & Kaufman's pseudoinverse): the default
    rigid,    ///< as rigid as possible where the material is (rigid.h): bends and twists come out as such
};

std::string to_string(Solver solver);

struct Edit {
    std::vector<Constraint> constraints; ///< rows, each named by its entry's JSON path, e.g. "edits[0].constraints[2]" (a frame
                                         ///< is four rows: a move and three turns; a connect with "at" two moves)
    Solver solver = Solver::min_norm;
    bool preserve_volume = false;        ///< keep the material's volume (det J = 1 over it), either solver
};

struct EditScript {
    LatticeSpec lattice; ///< defaults: 9^3, uniform, padding 0.25
    std::vector<Edit> edits;
};

/// Parse an edit script from text; `source` names it in messages. @throw InvalidInput.
EditScript parse_edit_script(const std::string& text, const std::string& source);

/// Read and parse an edit file. @throw IOError when it cannot be read, InvalidInput when it is malformed.
EditScript read_edit_file(const std::string& path);

} // namespace voxwarp

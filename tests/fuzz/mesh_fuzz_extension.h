// The format a fuzz input's first byte picks, shared by the fuzzer and the test that replays its regressions:
// byte % 8 of 0-3 is OBJ, OFF, PLY, STL (byte % 4, as before .om was added), 4-7 OpenMesh's binary .om.
#pragma once

#include <cstdint>

inline const char* mesh_fuzz_extension(std::uint8_t first) {
    static const char* extensions[] = {".obj", ".off", ".ply", ".stl"};
    return first % 8 < 4 ? extensions[first % 4] : ".om";
}

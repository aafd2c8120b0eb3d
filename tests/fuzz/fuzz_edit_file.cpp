// libFuzzer target: the edit-file parser on arbitrary text must either return a script or throw InvalidInput.
#include <voxwarp/edit_file.h>
#include <voxwarp/errors.h>

#include <cmath>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    try {
        const voxwarp::EditScript script = voxwarp::parse_edit_script(std::string(reinterpret_cast<const char*>(data), size), "fuzz.json");
        for (const auto& edit : script.edits)
            for (const auto& c : edit.constraints)
                if (!c.point.allFinite() || !c.to.allFinite() || !c.offset.allFinite()) __builtin_trap(); // validation let a NaN through
    } catch (const voxwarp::InvalidInput&) {
    }
    return 0;
}

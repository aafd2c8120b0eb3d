#include <voxwarp/basis.h>
#include <voxwarp/errors.h>

#include <string>

namespace voxwarp {

BasisTable::BasisTable(int g) : granularity(g) {
    if (g < 1) throw InvalidInput("basis table: granularity " + std::to_string(g) + " must be >= 1");
    values.resize(std::size_t(g) + 1);
    for (int e = 0; e <= g; ++e) values[std::size_t(e)] = cubic_basis(double(e) / g);
}

} // namespace voxwarp

/// @file messages.h
/// @brief Other libraries' error text made fit for one line of ours.
#pragma once

#include <string>
#include <string_view>

namespace voxwarp::internal {

/// The first line of `text`, runs of blanks as one space, control and non-ASCII bytes as '?', cut to `limit`
/// characters ("..." after). A truncated .vdb made OpenVDB quote 1.2 GB of blanks as a map type's name.
inline std::string excerpt(std::string_view text, std::size_t limit = 200) {
    const std::size_t line_end = text.find('\n');
    if (line_end != std::string_view::npos) text = text.substr(0, line_end);
    std::string out;
    for (const char c : text) {
        if (out.size() >= limit) return out + "...";
        const auto u = static_cast<unsigned char>(c);
        if (c == ' ' || c == '\t' || c == '\r') {
            if (!out.empty() && out.back() != ' ') out += ' ';
        } else {
            out += u < 0x20 || u >= 0x7f ? '?' : c;
        }
    }
    while (!out.empty() && out.back() == ' ') out.pop_back();
    return out;
}

} // namespace voxwarp::internal

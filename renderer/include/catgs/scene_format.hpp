// Which reader a scene file needs. Formats with a signature are recognised by their first
// bytes whatever the file is called (a .ply may hold SuperSplat's compressed layout, which
// only its header tells apart); the headerless .splat is recognised by its extension.
// load_scene dispatches from read_scene_file, the one place a format meets its reader.
#pragma once

#include <string>
#include <string_view>

#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"

namespace catgs {

enum class SceneFormat {
    unknown,
    ply,             ///< graphdeco 3DGS PLY (read_ply)
    compressed_ply,  ///< SuperSplat .compressed.ply: element chunk + packed vertex (read_compressed_ply)
    splat,           ///< antimatter15 .splat, 32-byte records (read_splat)
    spz,             ///< Niantic .spz: a gzip stream, or an "NGSP" header for version 4 (read_spz)
    sog,             ///< PlayCanvas SOG: a zip of WebP images and meta.json
    sog_meta,        ///< an unbundled SOG: meta.json beside its WebP images
    glb,             ///< glTF binary with Gaussian splat attributes
};

/// The format's name in messages and docs ("ply", "compressed ply", ".spz", ...).
std::string_view scene_format_name(SceneFormat format);

/// The format of the file at `path` from its first bytes (a PLY header up to 64 KiB), or from
/// its extension for .splat. Throws catgs::Error when the file cannot be opened.
SceneFormat detect_scene_format(const std::string& path);

/// Reads the file with the reader of detect_scene_format's answer; an unrecognised file is
/// an error naming its extension and first bytes.
Scene read_scene_file(const std::string& path, const LoadOptions& options, LoadReport* report);

}  // namespace catgs

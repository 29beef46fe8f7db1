// The PLY reader on bad files: each broken header, count or value gives one line that names
// the file, the problem and where it is, without allocating for counts the file cannot hold.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "scene_io_fixtures.hpp"

namespace {

using namespace catgs::scene_io_test;

// =======================================================================================
// Bad input: header.

void expect_ply_error(const std::string& bytes, const std::vector<std::string>& parts,
                      const std::string& name = "bad.ply") {
    std::string path = tmp_path(name);
    write_file(path, bytes);
    expect_error([&] { catgs::read_ply(path); }, path, parts);
}

TEST(SceneIoBadPly, NotAPly) {
    expect_ply_error("PK\x03\x04 this is a zip", {"not a PLY file", "byte offset 0"});
    expect_ply_error("", {"not a PLY file", "byte offset 0"});
    expect_ply_error("plyx\n", {"not a PLY file"});
}

TEST(SceneIoBadPly, MissingEndHeader) {
    std::string header = graphdeco_ply(1, 0).header();
    header = header.substr(0, header.find("end_header"));
    expect_ply_error(header, {"header ends without end_header", "byte offset " + std::to_string(header.size())});
}

TEST(SceneIoBadPly, HeaderTooLargeIsBounded) {
    std::string bytes = "ply\nformat binary_little_endian 1.0\n";
    const std::string comment = "comment " + std::string(100, 'c') + "\n";
    while (bytes.size() < (std::size_t{3} << 20)) bytes += comment;
    expect_ply_error(bytes, {"no end_header within the first 1048576 bytes", "byte offset 1048576"});
}

TEST(SceneIoBadPly, HeaderLineTooLong) {
    expect_ply_error("ply\nformat ascii 1.0\ncomment " + std::string(10000, 'x') + "\nend_header\n",
                     {"header line longer than 8192 bytes", "header line 3"});
    // A binary blob after the magic has no newline for megabytes.
    expect_ply_error("ply\n" + std::string(std::size_t{2} << 20, '\x01'), {"header line longer", "header line 2"});
}

TEST(SceneIoBadPly, UnknownFormat) {
    Ply ply = graphdeco_ply(1, 0, "binary_middle_endian");
    expect_ply_error(ply.bytes(), {"unknown format 'binary_middle_endian'", "header line 2"});
    std::string v2 = graphdeco_ply(1, 0).bytes();
    v2.replace(v2.find("1.0"), 3, "2.0");
    expect_ply_error(v2, {"unknown format 'format binary_little_endian 2.0'", "header line 2"});
    std::string none = graphdeco_ply(1, 0).bytes();
    none.erase(none.find("format"), std::string("format binary_little_endian 1.0\n").size());
    expect_ply_error(none, {"no format line", "header line"});
}

TEST(SceneIoBadPly, UnknownPropertyType) {
    std::string bytes = graphdeco_ply(1, 0).bytes();
    bytes.replace(bytes.find("float ny"), 5, "float16");
    expect_ply_error(bytes, {"unknown property type 'float16'", "'ny'", "header line 9"});
}

TEST(SceneIoBadPly, ListPropertyInVertex) {
    std::string header = graphdeco_ply(1, 0).header();
    header.insert(header.find("end_header"), "property list uchar float normals\n");
    expect_ply_error(header, {"list property 'normals'", "vertex element", "not supported", "header line"});
}

TEST(SceneIoBadPly, MalformedHeaderLines) {
    const std::string base = graphdeco_ply(1, 0).bytes();
    auto with = [&](const std::string& from, const std::string& to) {
        std::string b = base;
        b.replace(b.find(from), from.size(), to);
        return b;
    };
    expect_ply_error(with("element vertex 1", "element vertex"),
                     {"malformed header line 'element vertex'", "header line 4"});
    expect_ply_error(with("element vertex 1", "element vertex -1"),
                     {"malformed element line", "'-1'", "header line 4"});
    expect_ply_error(with("element vertex 1", "element vertex 1x"), {"malformed element line", "header line 4"});
    expect_ply_error(with("element vertex 1", "element vertex 18446744073709551616"),
                     {"not a non-negative 64-bit integer", "header line 4"});
    expect_ply_error(with("property float x", "property float"),
                     {"malformed header line 'property float'", "header line 5"});
    expect_ply_error(with("property float x", "property float x y"), {"malformed header line", "header line 5"});
    expect_ply_error(with("property float x", "property list uchar x"), {"malformed header line", "header line 5"});
    expect_ply_error(with("comment fixture", "property float q"),
                     {"property line before any element", "header line 3"});
    expect_ply_error(with("comment fixture", "colour red"), {"unknown header keyword 'colour'", "header line 3"});
    expect_ply_error(with("end_header", "end_header now"), {"malformed header line", "end_header"});
    expect_ply_error(with("element vertex 1", "element points 1"), {"no vertex element"});
    expect_ply_error(with("comment fixture", "element vertex 0"), {"second vertex element", "header line 4"});
    expect_ply_error(with("comment fixture", "format ascii 1.0"), {"second format line", "header line 3"});
    std::string face = with("comment fixture", "element face 1\nproperty list float int idx");
    expect_ply_error(face, {"list count type 'float'", "'idx'", "not an integer type", "header line 4"});
}

TEST(SceneIoBadPly, MissingRequiredProperties) {
    Ply ply = graphdeco_ply(1, 0);
    std::erase_if(ply.props, [](const Prop& p) { return p.name == "opacity" || p.name == "rot_3" || p.name == "x"; });
    expect_ply_error(ply.bytes(),
                     {"missing required properties 'x', 'opacity', 'rot_3'", "vertex element", "header line 4"});
    Ply one = graphdeco_ply(1, 0);
    std::erase_if(one.props, [](const Prop& p) { return p.name == "f_dc_2"; });
    expect_ply_error(one.bytes(), {"missing required property 'f_dc_2'"});
}

TEST(SceneIoBadPly, FRestCountAndGaps) {
    Ply ten = graphdeco_ply(1, 1);
    ten.props.push_back({"float", "f_rest_9"});
    expect_ply_error(ten.bytes(), {"10 f_rest_* properties", "expected 0, 9, 24 or 45", "header line 4"});
    Ply gap = graphdeco_ply(1, 1);
    for (auto& p : gap.props)
        if (p.name == "f_rest_4") p.name = "f_rest_12";
    expect_ply_error(gap.bytes(), {"missing required property 'f_rest_4'"});
    Ply duplicate = graphdeco_ply(1, 0);
    duplicate.props.push_back({"float", "scale_1"});
    expect_ply_error(duplicate.bytes(), {"duplicate property 'scale_1'"});
}

// =======================================================================================
// Bad input: counts and data.

TEST(SceneIoBadPly, ZeroVertices) {
    Ply ply = graphdeco_ply(0, 0);
    expect_ply_error(ply.bytes(), {"no Gaussians", "0 records", "header line 4"});
}

TEST(SceneIoBadPly, TruncatedBinary) {
    Ply ply = graphdeco_ply(10, 0);
    std::string bytes = ply.bytes();
    bytes.pop_back();
    const std::size_t stride = 17 * 4;
    expect_ply_error(bytes, {"element 'vertex' declares 10 records", "need " + std::to_string(10 * stride) + " bytes",
                             "only " + std::to_string(10 * stride - 1) + " bytes follow",
                             "byte offset " + std::to_string(ply.header().size())});
    ply.count = "11";
    expect_ply_error(ply.bytes(), {"declares 11 records"});
}

TEST(SceneIoBadPly, HugeCountsFailFastWithoutAllocating) {
    for (const std::string format : {"binary_little_endian", "ascii"}) {
        SCOPED_TRACE(format);
        Ply ply = graphdeco_ply(2, 3, format);
        ply.count = "1000000000000";
        auto start = std::chrono::steady_clock::now();
        expect_ply_error(ply.bytes(), {"declares 1000000000000 records", "bytes follow", "byte offset"});
        EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
        ply.count = "18446744073709551615";
        expect_ply_error(ply.bytes(), {"declares 18446744073709551615 records: too many", "header line 4"});
        ply.count = "3074457345618258603";  // * 62 * 4 wraps to a small number in 64 bits
        expect_ply_error(ply.bytes(), {"too many"});
    }
    // An element before the vertex with a huge count: fixed size and walked (list) variants.
    Ply before = graphdeco_ply(2, 0);
    before.before_header = "element camera 1000000000000\nproperty double fx\n";
    expect_ply_error(before.bytes(), {"element 'camera' declares 1000000000000 records"});
    before.before_header = "element edge 1000000000000\nproperty list uchar int ids\n";
    expect_ply_error(before.bytes(), {"data ends inside element 'edge'", "record", "'ids'"});
    before.before_header = "element edge 2\nproperty list uint int ids\n";
    before.before_data = std::string("\xff\xff\xff\x0f", 4);
    expect_ply_error(before.bytes(), {"data ends inside element 'edge'", "record 0, property 'ids'"});
    before.before_header = "element edge 2\nproperty list int int ids\n";
    before.before_data = std::string("\xff\xff\xff\xff", 4);
    expect_ply_error(before.bytes(), {"negative list length -1", "record 0, property 'ids'"});
}

// A file that ends before the data of an element declared after the vertices was cut short:
// refused naming that element, whether its records have a fixed size (checked by size), lists
// (walked) or ASCII lines; complete or empty trailing elements still load.
TEST(SceneIoBadPly, TruncatedElementAfterTheVertices) {
    Ply fixed = graphdeco_ply(2, 0);
    fixed.after_header = "element face 1\nproperty float quality\nproperty int id\n";
    expect_ply_error(fixed.bytes(), {"element 'face' declares 1 records", "need 8 bytes", "only 0 bytes follow",
                                     "byte offset " + std::to_string(fixed.bytes().size())});
    fixed.after_data = std::string(3, '\0');
    expect_ply_error(fixed.bytes(), {"element 'face' declares 1 records", "need 8 bytes", "only 3 bytes follow"});
    fixed.after_data = std::string(8, '\0');
    const std::string complete = tmp_path("trailing-fixed.ply");
    write_file(complete, fixed.bytes());
    EXPECT_EQ(catgs::read_ply(complete).count(), 2u);

    for (const std::string format : {"binary_little_endian", "binary_big_endian"}) {
        SCOPED_TRACE(format);
        Ply list = graphdeco_ply(2, 0, format);
        list.after_header = "element face 1\nproperty list uchar int vertex_indices\n";
        expect_ply_error(list.bytes(), {"data ends inside element 'face'", "record 0, property 'vertex_indices'"});
        list.after_data = std::string("\x03", 1) + std::string(8, '\0');  // 3 indices, 2 present
        expect_ply_error(list.bytes(), {"data ends inside element 'face'", "record 0, property 'vertex_indices'"});
    }

    Ply ascii = graphdeco_ply(2, 0, "ascii");
    ascii.after_header = "element face 2\nproperty list uchar int vertex_indices\n";
    ascii.after_data = "3 0 1 0\n";
    expect_ply_error(ascii.bytes(), {"data ends inside element 'face'", "record 1"});
    ascii.after_data = "";
    expect_ply_error(ascii.bytes(), {"data ends inside element 'face'", "record 0"});

    Ply empty = graphdeco_ply(2, 0);
    empty.after_header = "element face 0\nproperty list uchar int vertex_indices\n";
    const std::string none = tmp_path("trailing-empty.ply");
    write_file(none, empty.bytes());
    EXPECT_EQ(catgs::read_ply(none).count(), 2u);
}

// Data past the last element means the header declared fewer records than the file holds:
// refused, naming the element and where its data ends, rather than loading part of the scene.
// ASCII files may still end with blank lines.
TEST(SceneIoBadPly, DataAfterTheLastElement) {
    for (const std::string format : {"binary_little_endian", "binary_big_endian"}) {
        SCOPED_TRACE(format);
        Ply ply = graphdeco_ply(4, 0, format);
        const std::string all = ply.bytes();
        ply.count = "3";  // the fourth record is left over
        const std::size_t end = all.size() - 17 * 4;
        expect_ply_error(ply.bytes(), {"68 bytes after the last element 'vertex', which ends at byte " +
                                           std::to_string(end) + ": the header declares fewer records",
                                       "byte offset " + std::to_string(end)});
        Ply face = graphdeco_ply(2, 0, format);
        face.after_header = "element face 1\nproperty float quality\n";
        face.after_data = std::string(5, '\0');
        expect_ply_error(face.bytes(), {"1 bytes after the last element 'face'"});
    }
    Ply ascii = graphdeco_ply(3, 0, "ascii");
    ascii.count = "2";
    expect_ply_error(ascii.bytes(), {"data after the last element 'vertex'", "the header declares fewer records"});
    ascii.count = "3";
    ascii.after_data = "\n  \r\n\t\n";
    const std::string blank_tail = tmp_path("blank-tail.ply");
    write_file(blank_tail, ascii.bytes());
    EXPECT_EQ(catgs::read_ply(blank_tail).count(), 3u);
}

// LoadOptions::max_records (the fuzz targets' allocation cap): a file that declares more
// records is refused before anything is allocated for it; the default changes nothing.
TEST(SceneIoLimits, MaxRecordsRefusesLargerFiles) {
    const std::string ply = tmp_path("limit.ply");
    write_file(ply, graphdeco_ply(3, 0).bytes());
    catgs::LoadOptions options;
    EXPECT_EQ(options.max_records, std::numeric_limits<std::uint64_t>::max());
    options.max_records = 2;
    expect_error([&] { catgs::read_ply(ply, options); }, ply,
                 {"3 records exceed the limit of 2", "(LoadOptions::max_records)"});
    options.max_records = 3;
    EXPECT_EQ(catgs::read_ply(ply, options).count(), 3u);

    const std::string splat = tmp_path("limit.splat");
    write_file(splat, splat_bytes({SplatRecord{}, SplatRecord{}}));
    options.max_records = 1;
    expect_error([&] { catgs::read_splat(splat, options); }, splat,
                 {"2 records exceed the limit of 1", "(LoadOptions::max_records)"});
}

// LoadOptions::max_scene_bytes: a memory cap must be charged at the file's own SH degree, which
// a record count derived from one degree's cost cannot do (degree 3 costs 4.2 times degree 0).
TEST(SceneIoLimits, MaxSceneBytesChargesTheFilesShDegree) {
    const std::size_t expected[] = {56, 92, 152, 236};
    catgs::LoadOptions options;
    EXPECT_EQ(options.max_scene_bytes, std::numeric_limits<std::uint64_t>::max());
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        SCOPED_TRACE(degree);
        const std::size_t each = catgs::scene_bytes_per_gaussian(degree);
        EXPECT_EQ(each, expected[degree]);
        const std::string ply = tmp_path("budget" + std::to_string(degree) + ".ply");
        write_file(ply, graphdeco_ply(3, degree).bytes());
        options.max_scene_bytes = 3 * each - 1;
        expect_error([&] { catgs::read_ply(ply, options); }, ply,
                     {"3 records of SH degree " + std::to_string(degree) + " at " + std::to_string(each) +
                          " bytes each exceed the limit of " + std::to_string(3 * each - 1) + " bytes",
                      "(LoadOptions::max_scene_bytes)"});
        options.max_scene_bytes = 3 * each;
        const catgs::Scene s = catgs::read_ply(ply, options);
        EXPECT_EQ(s.count(), 3u);
        EXPECT_EQ(s.bytes(), 3 * each);
    }
}

TEST(SceneIoBadPly, AsciiMissingExtraAndUnparsableValues) {
    Ply ply = graphdeco_ply(5, 0, "ascii");
    const std::string header = ply.header();
    std::string data = ply.data();
    auto line_start = [&](int record) {
        std::size_t pos = 0;
        for (int i = 0; i < record; ++i) pos = data.find('\n', pos) + 1;
        return pos;
    };
    {
        std::string d = data;
        std::size_t end = d.find('\n', line_start(3));
        d.erase(d.rfind(' ', end), end - d.rfind(' ', end));  // drop the last value (rot_3)
        expect_ply_error(header + d, {"missing value", "16 of 17", "record 3, property 'rot_3'"});
    }
    {
        std::string d = data;
        d.insert(d.find('\n', line_start(2)), " 7");
        expect_ply_error(header + d, {"more than 17 values", "record 2"});
    }
    {
        std::string d = data;
        std::size_t opacity_at = line_start(4);
        for (int i = 0; i < 9; ++i) opacity_at = d.find(' ', opacity_at) + 1;  // 10th token: opacity
        d.replace(opacity_at, d.find(' ', opacity_at) - opacity_at, "0.5abc");
        expect_ply_error(header + d, {"cannot parse '0.5abc' as a number", "record 4, property 'opacity'"});
    }
    {
        std::string d = data.substr(0, line_start(4));
        ply.count = "5";
        expect_ply_error(header + d, {"data ends after 4 of 5", "record 4, property 'x'"});
    }
}

TEST(SceneIoBadPly, NonFiniteValuesNameRecordAndProperty) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    for (const std::string name : {"x", "z", "f_dc_1", "f_rest_7", "opacity", "scale_2", "rot_0", "rot_3"})
        for (const std::string format : {"binary_little_endian", "ascii"})
            for (double bad : {nan, inf, -inf}) {
                SCOPED_TRACE(name + " " + format);
                Ply ply = graphdeco_ply(5, 1, format);
                ply.rows[3][name] = bad;
                expect_ply_error(ply.bytes(), {"non-finite value", "record 3, property '" + name + "'"});
            }
}

TEST(SceneIoBadPly, ValuesThatOverflowAfterActivation) {
    Ply ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[1]["scale_1"] = 100.0;  // exp(100) > FLT_MAX
    expect_ply_error(ply.bytes(), {"scale 100 overflows float", "record 1, property 'scale_1'"});
    ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[2]["f_dc_0"] = 1e300;
    expect_ply_error(ply.bytes(), {"overflows float", "record 2, property 'f_dc_0'"});
    ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[0]["y"] = 1e35;
    expect_ply_error(ply.bytes(), {"coordinate 1e+35", "record 0, property 'y'"});
    ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[0]["rot_2"] = 1e300;
    expect_ply_error(ply.bytes(), {"quaternion norm overflows", "record 0, properties 'rot_0'..'rot_3'"});
}

TEST(SceneIoBadPly, ZeroNormQuaternion) {
    Ply ply = graphdeco_ply(6, 0);
    for (int c = 0; c < 4; ++c) ply.rows[4]["rot_" + std::to_string(c)] = 0.0;
    expect_ply_error(ply.bytes(), {"zero-norm quaternion", "record 4", "'rot_0'..'rot_3'"});
}

}  // namespace

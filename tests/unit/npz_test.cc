#include "motionpipe/formats/npz.h"

#include <gtest/gtest.h>

#include "motionpipe/formats/npy.h"
#include "motionpipe/formats/zip.h"

namespace motionpipe {
namespace {

TEST(Npy, RoundTripsEveryDType) {
  const std::vector<NpyArray> arrays = {NpyArray::Float32({2, 3}, {1, 2, 3, 4, 5, -6.5f}),
                                        NpyArray::Float64({3}, {1e300, -2, 0.5}),
                                        NpyArray::Int32({2}, {-7, 1 << 30}),
                                        NpyArray::Int64({1}, {-(int64_t{1} << 50)}),
                                        NpyArray::Bool({4}, {1, 0, 0, 1}),
                                        NpyArray::UInt8({2}, {0, 255}),
                                        NpyArray::Strings({3}, {"walk", "wave — right hand", ""}),
                                        NpyArray::ScalarFloat64(29.97)};
  for (const NpyArray& a : arrays) {
    const std::string bytes = SerializeNpy(a);
    // numpy aligns the data start to 64 bytes.
    const size_t header =
        10 + (static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8));
    EXPECT_EQ(header % 64, 0u);
    auto back = ParseNpy(bytes, "a.npy");
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_EQ(back->dtype, a.dtype);
    EXPECT_EQ(back->shape, a.shape);
    EXPECT_EQ(back->bytes, a.bytes);
  }
  auto strings = ParseNpy(SerializeNpy(arrays[6]), "s.npy")->ToStrings("s");
  ASSERT_TRUE(strings.ok());
  EXPECT_EQ((*strings)[1], "wave — right hand");
  EXPECT_EQ((*strings)[2], "");
}

std::string Header(const std::string& dict) {
  std::string out = "\x93NUMPY";
  out.push_back(1);
  out.push_back(0);
  out.push_back(static_cast<char>(dict.size()));
  out.push_back(0);
  return out + dict;
}

TEST(Npy, ReadsFortranOrderAndBigEndian) {
  // [[1, 2, 3], [4, 5, 6]] stored column-major as int16 big-endian.
  std::string bytes = Header("{'descr': '>i2', 'fortran_order': True, 'shape': (2, 3), }\n");
  for (int v : {1, 4, 2, 5, 3, 6}) {
    bytes.push_back(0);
    bytes.push_back(static_cast<char>(v));
  }
  auto a = ParseNpy(bytes, "f.npy");
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  auto values = a->ToInt64("f");
  ASSERT_TRUE(values.ok());
  EXPECT_EQ(*values, (std::vector<int64_t>{1, 2, 3, 4, 5, 6}));
}

TEST(Npy, BadInputGivesNamedErrors) {
  const auto expect_error = [](const std::string& bytes, const std::string& fragment) {
    auto a = ParseNpy(bytes, "bad.npy");
    ASSERT_FALSE(a.ok()) << fragment;
    EXPECT_NE(a.status().message().find("bad.npy"), std::string::npos);
    EXPECT_NE(a.status().message().find(fragment), std::string::npos) << a.status().message();
  };
  expect_error("hello world", "bad magic");
  expect_error(Header("{'descr': '|O', 'fortran_order': False, 'shape': (2,), }\n"),
               "object arrays");
  expect_error(Header("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (2,), }\n"),
               "structured");
  expect_error(Header("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }\n") + "abc",
               "truncated data");
  expect_error(
      Header("{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999, 99999999999), }\n"),
      "overflows");
  expect_error(Header("{'descr': '<f2', 'fortran_order': False, 'shape': (1,), }\n") + "ab",
               "unsupported dtype");
  expect_error(Header("{'descr': '<f4', 'shape': (1,), }\n"), "missing");
  auto strings = NpyArray::Strings({1}, {"x"});
  EXPECT_FALSE(strings.ToFloat32("s").ok());
  EXPECT_FALSE(NpyArray::Float32({1}, {1}).ToStrings("f").ok());
}

TEST(Zip, StoredAndDeflatedMembersRoundTrip) {
  ZipWriter writer;
  const std::string big(100000, 'x');
  writer.Add("a.npy", "hello", false);
  writer.Add("b.npy", big, true);
  writer.Add("empty.npy", "", true);
  const std::string archive = writer.Finish();
  EXPECT_LT(archive.size(), 2000u);  // the repetitive member compressed
  auto members = ReadZip(archive, "t.npz");
  ASSERT_TRUE(members.ok()) << members.status().ToString();
  ASSERT_EQ(members->size(), 3u);
  EXPECT_EQ((*members)[0].data, "hello");
  EXPECT_EQ((*members)[1].data, big);
  EXPECT_EQ((*members)[2].data, "");
}

TEST(Zip, CorruptionAndTruncationAreDetected) {
  ZipWriter writer;
  writer.Add("a.npy", "some payload that will be damaged", false);
  const std::string archive = writer.Finish();
  std::string flipped = archive;
  const size_t at = archive.find("payload");
  ASSERT_NE(at, std::string::npos);
  flipped[at] ^= 0x55;  // inside the stored data
  auto crc = ReadZip(flipped, "c.npz");
  ASSERT_FALSE(crc.ok());
  EXPECT_NE(crc.status().message().find("CRC mismatch"), std::string::npos);
  for (size_t cut : {size_t{0}, size_t{10}, archive.size() / 2, archive.size() - 1}) {
    auto truncated = ReadZip(archive.substr(0, cut), "t.npz");
    EXPECT_FALSE(truncated.ok()) << cut;
    EXPECT_NE(truncated.status().message().find("t.npz"), std::string::npos);
  }
}

TEST(Zip, StoredMembersAreAlignedForInPlaceUse) {
  ZipWriter writer;
  writer.Add("odd-name.npy", "first", false);
  writer.Add("b.npy", std::string(1000, 'y'), true);
  writer.Add("third-member.npy", "third", false);
  const std::string archive = writer.Finish();
  auto entries = ListZip(archive, "a.npz");
  ASSERT_TRUE(entries.ok()) << entries.status().ToString();
  ASSERT_EQ(entries->size(), 3u);
  for (const ZipEntry& entry : *entries) {
    if (entry.method != 0) continue;
    EXPECT_EQ(static_cast<size_t>(entry.payload.data() - archive.data()) % 64, 0u) << entry.name;
  }
  EXPECT_EQ((*entries)[2].payload, "third");
  auto data = ExtractZipEntry((*entries)[1], "a.npz");
  ASSERT_TRUE(data.ok());
  EXPECT_EQ(*data, std::string(1000, 'y'));
}

TEST(Npz, ArraysOfStoredArchivesAreAlignedInTheFile) {
  Npz npz;
  npz.Add("format", NpyArray::ScalarString("x"));
  npz.Add("poses", NpyArray::Float32({3, 22, 3}, std::vector<float>(198, 0.25f)));
  const std::string bytes = SerializeNpz(npz, false);
  auto entries = ListZip(bytes, "a.npz");
  ASSERT_TRUE(entries.ok());
  for (const ZipEntry& entry : *entries) {
    auto view = ParseNpyView(entry.payload, entry.name);
    ASSERT_TRUE(view.ok());
    EXPECT_EQ(static_cast<size_t>(view->data.data() - bytes.data()) % 64, 0u) << entry.name;
    EXPECT_TRUE(view->Native());
  }
  // Only the chosen arrays are extracted.
  auto some = ParseNpz(bytes, "a.npz", {"poses"});
  ASSERT_TRUE(some.ok());
  EXPECT_EQ(some->arrays().size(), 1u);
  EXPECT_NE(some->Find("poses"), nullptr);
}

TEST(Npz, RoundTripAndShapeChecks) {
  Npz npz;
  npz.Add("poses", NpyArray::Float32({2, 22, 3}, std::vector<float>(132, 0.5f)));
  npz.Add("name", NpyArray::ScalarString("x"));
  for (bool compress : {false, true}) {
    auto back = ParseNpz(SerializeNpz(npz, compress), "m.npz");
    ASSERT_TRUE(back.ok());
    EXPECT_TRUE(GetShaped(*back, "poses", {-1, 22, 3}, "m.npz").ok());
    auto wrong = GetShaped(*back, "poses", {-1, 24, 3}, "m.npz");
    ASSERT_FALSE(wrong.ok());
    EXPECT_NE(wrong.status().message().find("has shape (2, 22, 3), expected (N, 24, 3)"),
              std::string::npos);
    auto missing = back->Get("trans", "m.npz");
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.status().message().find("missing array 'trans' (present: poses, name)"),
              std::string::npos);
  }
}

}  // namespace
}  // namespace motionpipe

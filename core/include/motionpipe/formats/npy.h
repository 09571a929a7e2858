// numpy's .npy format (versions 1.0, 2.0 and 3.0): read and write bool, (u)int8/16/32/64, float32,
// float64 and unicode arrays in C or Fortran order, either byte order; arrays read back in C order,
// little-endian. Object arrays (pickles) and structured dtypes are refused with a clear message.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe {

enum class DType {
  kBool,
  kInt8,
  kUInt8,
  kInt16,
  kUInt16,
  kInt32,
  kUInt32,
  kInt64,
  kUInt64,
  kFloat32,
  kFloat64,
  kUnicode
};

// numpy's name for the dtype ("float32", "<U12" for unicode).
std::string DTypeName(DType dtype, int64_t item_size);

struct NpyArray {
  DType dtype = DType::kFloat32;
  std::vector<int64_t> shape;  // empty = scalar
  int64_t item_size = 4;       // bytes per element; unicode: 4 * characters
  std::string bytes;           // elements in C order, little-endian

  int64_t num_elements() const;
  std::string ShapeString() const;  // "(3, 22, 3)"

  static NpyArray Float32(std::vector<int64_t> shape, const std::vector<float>& values);
  static NpyArray Float64(std::vector<int64_t> shape, const std::vector<double>& values);
  static NpyArray Int32(std::vector<int64_t> shape, const std::vector<int32_t>& values);
  static NpyArray Int64(std::vector<int64_t> shape, const std::vector<int64_t>& values);
  static NpyArray UInt8(std::vector<int64_t> shape, const std::vector<uint8_t>& values);
  static NpyArray Bool(std::vector<int64_t> shape, const std::vector<uint8_t>& values);
  // UTF-8 in, stored as numpy unicode (UTF-32), width = the longest string (at least 1).
  static NpyArray Strings(std::vector<int64_t> shape, const std::vector<std::string>& values);
  static NpyArray ScalarFloat64(double value) { return Float64({}, {value}); }
  static NpyArray ScalarString(const std::string& value) { return Strings({}, {value}); }

  // Element conversions; InvalidArgument (naming `origin`) when the dtype cannot convert
  // (strings to numbers, numbers to strings). Integer/bool/float convert freely among themselves.
  Result<std::vector<float>> ToFloat32(const std::string& origin) const;
  Result<std::vector<double>> ToFloat64(const std::string& origin) const;
  Result<std::vector<int64_t>> ToInt64(const std::string& origin) const;
  Result<std::vector<std::string>> ToStrings(const std::string& origin) const;
};

// A parsed .npy header and where its data lie, without copying them.
struct NpyView {
  DType dtype = DType::kFloat32;
  int64_t item_size = 4;
  std::vector<int64_t> shape;
  int64_t count = 0;  // elements
  bool fortran = false;
  bool big_endian = false;
  size_t data_offset = 0;  // from the start of the .npy bytes
  std::string_view data;   // count * item_size bytes, as stored
  // True when the data can be read as a C-order little-endian array in place.
  bool Native() const { return !big_endian && (!fortran || shape.size() < 2); }
};
Result<NpyView> ParseNpyView(std::string_view bytes, const std::string& origin);

// Parses a whole .npy file held in memory. DataLoss names `origin` and what is wrong.
Result<NpyArray> ParseNpy(std::string_view bytes, const std::string& origin);
// The same, consuming `bytes`: the array takes over the buffer instead of copying it.
Result<NpyArray> ParseNpy(std::string&& bytes, const std::string& origin);
// Serialises as .npy version 1.0 (2.0 when the header needs it), 64-byte aligned like numpy.
std::string SerializeNpy(const NpyArray& array);

Result<NpyArray> ReadNpy(const std::string& path);
Status WriteNpy(const std::string& path, const NpyArray& array);

}  // namespace motionpipe

#include "motionpipe/formats/npy.h"

#include <algorithm>
#include <cstring>
#include <limits>

#include "motionpipe/base/file.h"

namespace motionpipe {

namespace {

struct DTypeInfo {
  DType dtype;
  char kind;  // numpy kind letter
  int size;   // bytes; 0 for unicode (variable)
};

constexpr DTypeInfo kDTypes[] = {
    {DType::kBool, 'b', 1},    {DType::kInt8, 'i', 1},    {DType::kUInt8, 'u', 1},
    {DType::kInt16, 'i', 2},   {DType::kUInt16, 'u', 2},  {DType::kInt32, 'i', 4},
    {DType::kUInt32, 'u', 4},  {DType::kInt64, 'i', 8},   {DType::kUInt64, 'u', 8},
    {DType::kFloat32, 'f', 4}, {DType::kFloat64, 'f', 8}, {DType::kUnicode, 'U', 0},
};

const DTypeInfo& Info(DType dtype) {
  for (const auto& info : kDTypes) {
    if (info.dtype == dtype) return info;
  }
  return kDTypes[0];
}

std::string Descr(const NpyArray& array) {
  const DTypeInfo& info = Info(array.dtype);
  if (array.dtype == DType::kUnicode) return "<U" + std::to_string(array.item_size / 4);
  const char order = info.size == 1 ? '|' : '<';
  return std::string(1, order) + info.kind + std::to_string(info.size);
}

bool MulOverflows(int64_t a, int64_t b, int64_t* out) {
  if (a < 0 || b < 0) return true;
  if (a != 0 && b > std::numeric_limits<int64_t>::max() / a) return true;
  *out = a * b;
  return false;
}

// A tiny reader for the header's Python dict literal: {'descr': '<f4', 'fortran_order': False,
// 'shape': (3, 4), }
class HeaderParser {
 public:
  explicit HeaderParser(std::string_view text) : text_(text) {}

  Status Parse(std::string* descr, bool* fortran, std::vector<int64_t>* shape) {
    bool have_descr = false, have_order = false, have_shape = false;
    SkipSpace();
    if (!Eat('{')) return Fail("header does not start with '{'");
    while (true) {
      SkipSpace();
      if (Eat('}')) break;
      std::string key;
      if (!ParseString(&key)) return Fail("expected a quoted key");
      SkipSpace();
      if (!Eat(':')) return Fail("expected ':' after key '" + key + "'");
      SkipSpace();
      if (key == "descr") {
        if (Peek() == '[') return Fail("structured dtypes are not supported");
        if (!ParseString(descr)) return Fail("descr is not a string");
        have_descr = true;
      } else if (key == "fortran_order") {
        if (text_.substr(pos_, 4) == "True") {
          *fortran = true;
          pos_ += 4;
        } else if (text_.substr(pos_, 5) == "False") {
          *fortran = false;
          pos_ += 5;
        } else {
          return Fail("fortran_order is not True or False");
        }
        have_order = true;
      } else if (key == "shape") {
        if (!Eat('(')) return Fail("shape is not a tuple");
        shape->clear();
        while (true) {
          SkipSpace();
          if (Eat(')')) break;
          int64_t value = 0;
          size_t digits = 0;
          while (pos_ < text_.size() && text_[pos_] >= '0' && text_[pos_] <= '9') {
            if (value > (std::numeric_limits<int64_t>::max() - 9) / 10)
              return Fail("shape entry too large");
            value = value * 10 + (text_[pos_] - '0');
            ++pos_;
            ++digits;
          }
          if (Peek() == 'L') ++pos_;  // Python 2 long suffix
          if (digits == 0) return Fail("shape entry is not a non-negative integer");
          shape->push_back(value);
          if (shape->size() > 32) return Fail("more than 32 dimensions");
          SkipSpace();
          if (Eat(',')) continue;
          if (Eat(')')) break;
          return Fail("malformed shape tuple");
        }
        have_shape = true;
      } else {
        return Fail("unexpected key '" + key + "'");
      }
      SkipSpace();
      if (Eat(',')) continue;
      SkipSpace();
      if (Eat('}')) break;
      return Fail("expected ',' or '}'");
    }
    if (!have_descr || !have_order || !have_shape)
      return Fail("descr, fortran_order or shape missing");
    return Status::Ok();
  }

 private:
  char Peek() const { return pos_ < text_.size() ? text_[pos_] : '\0'; }
  bool Eat(char c) {
    if (Peek() != c) return false;
    ++pos_;
    return true;
  }
  void SkipSpace() {
    while (pos_ < text_.size() &&
           (text_[pos_] == ' ' || text_[pos_] == '\n' || text_[pos_] == '\t'))
      ++pos_;
  }
  bool ParseString(std::string* out) {
    const char quote = Peek();
    if (quote != '\'' && quote != '"') return false;
    ++pos_;
    const size_t end = text_.find(quote, pos_);
    if (end == std::string_view::npos) return false;
    *out = std::string(text_.substr(pos_, end - pos_));
    pos_ = end + 1;
    return true;
  }
  Status Fail(const std::string& what) const { return DataLoss("malformed .npy header: " + what); }

  std::string_view text_;
  size_t pos_ = 0;
};

void AppendUtf8(uint32_t cp, std::string* out) {
  if (cp < 0x80) {
    out->push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out->push_back(static_cast<char>(0xC0 | (cp >> 6)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else if (cp < 0x10000) {
    out->push_back(static_cast<char>(0xE0 | (cp >> 12)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else {
    out->push_back(static_cast<char>(0xF0 | (cp >> 18)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  }
}

// Decodes UTF-8 leniently: an invalid or truncated sequence becomes U+FFFD.
std::vector<uint32_t> DecodeUtf8(const std::string& text) {
  std::vector<uint32_t> out;
  size_t k = 0;
  while (k < text.size()) {
    const auto lead = static_cast<unsigned char>(text[k]);
    size_t extra = 0;
    uint32_t cp = 0;
    if (lead < 0x80) {
      cp = lead;
    } else if ((lead >> 5) == 0x6) {
      extra = 1;
      cp = lead & 0x1F;
    } else if ((lead >> 4) == 0xE) {
      extra = 2;
      cp = lead & 0x0F;
    } else if ((lead >> 3) == 0x1E) {
      extra = 3;
      cp = lead & 0x07;
    } else {
      out.push_back(0xFFFD);
      ++k;
      continue;
    }
    bool valid = k + extra < text.size();
    for (size_t e = 1; valid && e <= extra; ++e) {
      const auto next = static_cast<unsigned char>(text[k + e]);
      valid = (next >> 6) == 0x2;
      cp = (cp << 6) | (next & 0x3F);
    }
    if (!valid) {
      out.push_back(0xFFFD);
      ++k;
      continue;
    }
    out.push_back(cp);
    k += extra + 1;
  }
  return out;
}

template <typename T>
NpyArray FromValues(DType dtype, std::vector<int64_t> shape, const std::vector<T>& values) {
  NpyArray array;
  array.dtype = dtype;
  array.shape = std::move(shape);
  array.item_size = sizeof(T);
  array.bytes.assign(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
  return array;
}

template <typename Out>
Result<std::vector<Out>> ConvertNumeric(const NpyArray& array, const std::string& origin) {
  if (array.dtype == DType::kUnicode) {
    return InvalidArgument(origin + ": holds strings (" + DTypeName(array.dtype, array.item_size) +
                           "), expected numbers");
  }
  const int64_t n = array.num_elements();
  std::vector<Out> out(static_cast<size_t>(n));
  const char* src = array.bytes.data();
  for (int64_t k = 0; k < n; ++k) {
    const char* p = src + k * array.item_size;
    switch (array.dtype) {
      case DType::kBool:
        out[static_cast<size_t>(k)] = static_cast<Out>(*p != 0);
        break;
#define MP_CONVERT(tag, type)                          \
  case tag: {                                          \
    type v;                                            \
    std::memcpy(&v, p, sizeof(type));                  \
    out[static_cast<size_t>(k)] = static_cast<Out>(v); \
    break;                                             \
  }
        MP_CONVERT(DType::kInt8, int8_t)
        MP_CONVERT(DType::kUInt8, uint8_t)
        MP_CONVERT(DType::kInt16, int16_t)
        MP_CONVERT(DType::kUInt16, uint16_t)
        MP_CONVERT(DType::kInt32, int32_t)
        MP_CONVERT(DType::kUInt32, uint32_t)
        MP_CONVERT(DType::kInt64, int64_t)
        MP_CONVERT(DType::kUInt64, uint64_t)
        MP_CONVERT(DType::kFloat32, float)
        MP_CONVERT(DType::kFloat64, double)
#undef MP_CONVERT
      case DType::kUnicode:
        break;
    }
  }
  return out;
}

}  // namespace

std::string DTypeName(DType dtype, int64_t item_size) {
  switch (dtype) {
    case DType::kBool:
      return "bool";
    case DType::kInt8:
      return "int8";
    case DType::kUInt8:
      return "uint8";
    case DType::kInt16:
      return "int16";
    case DType::kUInt16:
      return "uint16";
    case DType::kInt32:
      return "int32";
    case DType::kUInt32:
      return "uint32";
    case DType::kInt64:
      return "int64";
    case DType::kUInt64:
      return "uint64";
    case DType::kFloat32:
      return "float32";
    case DType::kFloat64:
      return "float64";
    case DType::kUnicode:
      return "<U" + std::to_string(item_size / 4);
  }
  return "?";
}

int64_t NpyArray::num_elements() const {
  int64_t n = 1;
  for (int64_t d : shape) n *= d;
  return n;
}

std::string NpyArray::ShapeString() const {
  std::string out = "(";
  for (size_t k = 0; k < shape.size(); ++k) {
    if (k) out += ", ";
    out += std::to_string(shape[k]);
  }
  if (shape.size() == 1) out += ",";
  return out + ")";
}

NpyArray NpyArray::Float32(std::vector<int64_t> shape, const std::vector<float>& values) {
  return FromValues(DType::kFloat32, std::move(shape), values);
}
NpyArray NpyArray::Float64(std::vector<int64_t> shape, const std::vector<double>& values) {
  return FromValues(DType::kFloat64, std::move(shape), values);
}
NpyArray NpyArray::Int32(std::vector<int64_t> shape, const std::vector<int32_t>& values) {
  return FromValues(DType::kInt32, std::move(shape), values);
}
NpyArray NpyArray::Int64(std::vector<int64_t> shape, const std::vector<int64_t>& values) {
  return FromValues(DType::kInt64, std::move(shape), values);
}
NpyArray NpyArray::UInt8(std::vector<int64_t> shape, const std::vector<uint8_t>& values) {
  return FromValues(DType::kUInt8, std::move(shape), values);
}
NpyArray NpyArray::Bool(std::vector<int64_t> shape, const std::vector<uint8_t>& values) {
  NpyArray array = FromValues(DType::kBool, std::move(shape), values);
  for (char& b : array.bytes) b = b ? 1 : 0;
  return array;
}

NpyArray NpyArray::Strings(std::vector<int64_t> shape, const std::vector<std::string>& values) {
  std::vector<std::vector<uint32_t>> decoded;
  size_t width = 1;
  for (const auto& value : values) {
    decoded.push_back(DecodeUtf8(value));
    width = std::max(width, decoded.back().size());
  }
  NpyArray array;
  array.dtype = DType::kUnicode;
  array.shape = std::move(shape);
  array.item_size = static_cast<int64_t>(width * 4);
  array.bytes.assign(values.size() * width * 4, '\0');
  for (size_t k = 0; k < decoded.size(); ++k) {
    for (size_t c = 0; c < decoded[k].size(); ++c) {
      const uint32_t cp = decoded[k][c];
      char* dst = array.bytes.data() + (k * width + c) * 4;
      dst[0] = static_cast<char>(cp & 0xFF);
      dst[1] = static_cast<char>((cp >> 8) & 0xFF);
      dst[2] = static_cast<char>((cp >> 16) & 0xFF);
      dst[3] = static_cast<char>((cp >> 24) & 0xFF);
    }
  }
  return array;
}

Result<std::vector<float>> NpyArray::ToFloat32(const std::string& origin) const {
  return ConvertNumeric<float>(*this, origin);
}
Result<std::vector<double>> NpyArray::ToFloat64(const std::string& origin) const {
  return ConvertNumeric<double>(*this, origin);
}
Result<std::vector<int64_t>> NpyArray::ToInt64(const std::string& origin) const {
  return ConvertNumeric<int64_t>(*this, origin);
}

Result<std::vector<std::string>> NpyArray::ToStrings(const std::string& origin) const {
  if (dtype != DType::kUnicode) {
    return InvalidArgument(origin + ": holds " + DTypeName(dtype, item_size) +
                           ", expected strings");
  }
  const int64_t n = num_elements();
  const int64_t width = item_size / 4;
  std::vector<std::string> out;
  out.reserve(static_cast<size_t>(n));
  for (int64_t k = 0; k < n; ++k) {
    std::string text;
    for (int64_t c = 0; c < width; ++c) {
      const auto* p = reinterpret_cast<const unsigned char*>(bytes.data() + (k * width + c) * 4);
      const uint32_t cp =
          uint32_t{p[0]} | (uint32_t{p[1]} << 8) | (uint32_t{p[2]} << 16) | (uint32_t{p[3]} << 24);
      if (cp == 0) break;
      if (cp > 0x10FFFF) return DataLoss(origin + ": invalid unicode code point");
      AppendUtf8(cp, &text);
    }
    out.push_back(std::move(text));
  }
  return out;
}

namespace {

// `owned`, when given, holds `bytes` and is consumed: the data move into the array without a copy.
}  // namespace

Result<NpyView> ParseNpyView(std::string_view bytes, const std::string& origin) {
  static constexpr char kMagic[] = "\x93NUMPY";
  if (bytes.size() < 10 || bytes.substr(0, 6) != std::string_view(kMagic, 6)) {
    return DataLoss(origin + ": not a .npy file (bad magic)");
  }
  const auto major = static_cast<unsigned char>(bytes[6]);
  size_t header_len = 0, header_start = 0;
  if (major == 1) {
    header_len = static_cast<unsigned char>(bytes[8]) |
                 (static_cast<size_t>(static_cast<unsigned char>(bytes[9])) << 8);
    header_start = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) return DataLoss(origin + ": truncated .npy header");
    header_len = 0;
    for (int k = 3; k >= 0; --k)
      header_len =
          (header_len << 8) | static_cast<unsigned char>(bytes[8 + static_cast<size_t>(k)]);
    header_start = 12;
  } else {
    return DataLoss(origin + ": unsupported .npy version " + std::to_string(major));
  }
  if (header_len > bytes.size() - header_start) return DataLoss(origin + ": truncated .npy header");
  std::string descr;
  NpyView array;
  Status parsed = HeaderParser(bytes.substr(header_start, header_len))
                      .Parse(&descr, &array.fortran, &array.shape);
  if (!parsed.ok()) return parsed.WithContext(origin);

  if (descr.size() < 2) return DataLoss(origin + ": bad dtype '" + descr + "'");
  char order = descr[0];
  std::string rest = descr.substr(1);
  if (order != '<' && order != '>' && order != '|' && order != '=') {
    order = '|';
    rest = descr;
  }
  const char kind = rest[0];
  int64_t size = 0;
  for (size_t k = 1; k < rest.size(); ++k) {
    if (rest[k] < '0' || rest[k] > '9' || size > 1'000'000)
      return DataLoss(origin + ": bad dtype '" + descr + "'");
    size = size * 10 + (rest[k] - '0');
  }
  if (kind == 'O') return DataLoss(origin + ": object arrays (Python pickles) are not supported");
  bool found = false;
  if (kind == 'U') {
    if (size <= 0) return DataLoss(origin + ": zero-width unicode dtype");
    array.dtype = DType::kUnicode;
    array.item_size = size * 4;
    found = true;
  } else {
    for (const auto& info : kDTypes) {
      if (info.kind == kind && info.size == size && info.dtype != DType::kUnicode) {
        array.dtype = info.dtype;
        array.item_size = size;
        found = true;
        break;
      }
    }
  }
  if (!found) return DataLoss(origin + ": unsupported dtype '" + descr + "'");

  auto shape_text = [&] {
    NpyArray probe;
    probe.shape = array.shape;
    return probe.ShapeString();
  };
  int64_t count = 1;
  for (int64_t d : array.shape) {
    if (MulOverflows(count, d, &count))
      return DataLoss(origin + ": shape " + shape_text() + " overflows");
  }
  int64_t total = 0;
  if (MulOverflows(count, array.item_size, &total))
    return DataLoss(origin + ": array size overflows");
  const size_t data_start = header_start + header_len;
  if (static_cast<uint64_t>(total) > bytes.size() - data_start) {
    return DataLoss(origin + ": truncated data: shape " + shape_text() + " of " +
                    DTypeName(array.dtype, array.item_size) + " needs " + std::to_string(total) +
                    " bytes, found " + std::to_string(bytes.size() - data_start));
  }
  array.big_endian = order == '>';
  array.data_offset = data_start;
  array.data = bytes.substr(data_start, static_cast<size_t>(total));
  array.count = count;
  return array;
}

namespace {

Result<NpyArray> ParseNpyImpl(std::string_view bytes, const std::string& origin,
                              std::string* owned) {
  MP_ASSIGN_OR_RETURN(const NpyView view, ParseNpyView(bytes, origin));
  NpyArray array;
  array.dtype = view.dtype;
  array.item_size = view.item_size;
  array.shape = view.shape;
  const bool fortran = view.fortran;
  const char order = view.big_endian ? '>' : '<';
  const int64_t count = view.count;
  const size_t data_start = view.data_offset;
  const auto total = static_cast<int64_t>(view.data.size());
  if (owned != nullptr) {
    owned->erase(0, data_start);
    owned->resize(static_cast<size_t>(total));
    array.bytes = std::move(*owned);
  } else {
    array.bytes.assign(bytes.data() + data_start, static_cast<size_t>(total));
  }

  // Big-endian numbers (and unicode) to little-endian.
  const int swap_unit = array.dtype == DType::kUnicode ? 4 : static_cast<int>(array.item_size);
  if (order == '>' && swap_unit > 1) {
    for (size_t k = 0; k + static_cast<size_t>(swap_unit) <= array.bytes.size();
         k += static_cast<size_t>(swap_unit)) {
      std::reverse(array.bytes.begin() + static_cast<std::ptrdiff_t>(k),
                   array.bytes.begin() + static_cast<std::ptrdiff_t>(k) + swap_unit);
    }
  }
  // Fortran order to C order.
  if (fortran && array.shape.size() > 1 && count > 0) {
    const size_t ndim = array.shape.size();
    std::string c_order(array.bytes.size(), '\0');
    std::vector<int64_t> index(ndim, 0);
    std::vector<int64_t> f_stride(ndim, 1);
    for (size_t d = 1; d < ndim; ++d) f_stride[d] = f_stride[d - 1] * array.shape[d - 1];
    for (int64_t linear = 0; linear < count; ++linear) {
      int64_t f_index = 0;
      for (size_t d = 0; d < ndim; ++d) f_index += index[d] * f_stride[d];
      std::memcpy(c_order.data() + linear * array.item_size,
                  array.bytes.data() + f_index * array.item_size,
                  static_cast<size_t>(array.item_size));
      for (size_t d = ndim; d-- > 0;) {
        if (++index[d] < array.shape[d]) break;
        index[d] = 0;
      }
    }
    array.bytes = std::move(c_order);
  }
  return array;
}

}  // namespace

Result<NpyArray> ParseNpy(std::string_view bytes, const std::string& origin) {
  return ParseNpyImpl(bytes, origin, nullptr);
}

Result<NpyArray> ParseNpy(std::string&& bytes, const std::string& origin) {
  const std::string_view view(bytes);
  return ParseNpyImpl(view, origin, &bytes);
}

std::string SerializeNpy(const NpyArray& array) {
  std::string dict = "{'descr': '" + Descr(array) +
                     "', 'fortran_order': False, 'shape': " + array.ShapeString() + ", }";
  // Pad with spaces so that magic + length + header + '\n' is a multiple of 64 (numpy's alignment).
  const bool v2 = dict.size() + 11 > 65535;
  const size_t prefix = v2 ? 12 : 10;
  size_t total = prefix + dict.size() + 1;
  const size_t padded = (total + 63) / 64 * 64;
  dict.append(padded - total, ' ');
  dict.push_back('\n');
  std::string out = "\x93NUMPY";
  out.push_back(static_cast<char>(v2 ? 2 : 1));
  out.push_back(0);
  const size_t len = dict.size();
  out.push_back(static_cast<char>(len & 0xFF));
  out.push_back(static_cast<char>((len >> 8) & 0xFF));
  if (v2) {
    out.push_back(static_cast<char>((len >> 16) & 0xFF));
    out.push_back(static_cast<char>((len >> 24) & 0xFF));
  }
  out += dict;
  out += array.bytes;
  return out;
}

Result<NpyArray> ReadNpy(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const std::string bytes, ReadFile(path));
  return ParseNpy(bytes, path);
}

Status WriteNpy(const std::string& path, const NpyArray& array) {
  return WriteFileAtomic(path, SerializeNpy(array));
}

}  // namespace motionpipe

#include "motionpipe/formats/zip.h"

#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <limits>

namespace motionpipe {

namespace {

constexpr uint32_t kLocalSig = 0x04034b50;
constexpr uint32_t kCentralSig = 0x02014b50;
constexpr uint32_t kEndSig = 0x06054b50;
constexpr uint32_t kZip64EndSig = 0x06064b50;
constexpr uint32_t kZip64LocatorSig = 0x07064b50;
constexpr uint32_t k32Max = 0xFFFFFFFFu;
// Deflate cannot expand data by more than ~1032:1; larger claims are corrupt (and would let a
// damaged file ask for terabytes).
constexpr uint64_t kMaxDeflateRatio = 1032;

uint16_t Get16(std::string_view s, size_t at) {
  return static_cast<uint16_t>(static_cast<unsigned char>(s[at]) |
                               (static_cast<unsigned char>(s[at + 1]) << 8));
}
uint32_t Get32(std::string_view s, size_t at) {
  return uint32_t{Get16(s, at)} | (uint32_t{Get16(s, at + 2)} << 16);
}
uint64_t Get64(std::string_view s, size_t at) {
  return uint64_t{Get32(s, at)} | (uint64_t{Get32(s, at + 4)} << 32);
}

void Put16(std::string* out, uint16_t v) {
  out->push_back(static_cast<char>(v & 0xFF));
  out->push_back(static_cast<char>(v >> 8));
}
void Put32(std::string* out, uint32_t v) {
  Put16(out, static_cast<uint16_t>(v & 0xFFFF));
  Put16(out, static_cast<uint16_t>(v >> 16));
}
void Put64(std::string* out, uint64_t v) {
  Put32(out, static_cast<uint32_t>(v & k32Max));
  Put32(out, static_cast<uint32_t>(v >> 32));
}

uint32_t Crc32(std::string_view data) {
  uLong crc = crc32(0L, Z_NULL, 0);
  size_t offset = 0;
  while (offset < data.size()) {
    const size_t chunk = std::min<size_t>(data.size() - offset, 1u << 30);
    crc =
        crc32(crc, reinterpret_cast<const Bytef*>(data.data() + offset), static_cast<uInt>(chunk));
    offset += chunk;
  }
  return static_cast<uint32_t>(crc);
}

Status Inflate(std::string_view compressed, uint64_t size, std::string* out,
               const std::string& where) {
  out->assign(size, '\0');
  z_stream stream{};
  if (inflateInit2(&stream, -MAX_WBITS) != Z_OK) return Internal(where + ": zlib init failed");
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(compressed.data()));
  stream.next_out = reinterpret_cast<Bytef*>(out->data());
  uint64_t in_left = compressed.size(), out_left = size;
  int rc = Z_OK;
  while (rc == Z_OK) {
    const uInt in_chunk = static_cast<uInt>(std::min<uint64_t>(in_left, 1u << 30));
    const uInt out_chunk = static_cast<uInt>(std::min<uint64_t>(out_left, 1u << 30));
    stream.avail_in = in_chunk;
    stream.avail_out = out_chunk;
    rc = inflate(&stream, Z_NO_FLUSH);
    in_left -= in_chunk - stream.avail_in;
    out_left -= out_chunk - stream.avail_out;
    if (rc == Z_OK && stream.avail_in == in_chunk && stream.avail_out == out_chunk)
      rc = Z_BUF_ERROR;
  }
  inflateEnd(&stream);
  if (rc != Z_STREAM_END) return DataLoss(where + ": deflate stream is corrupt or truncated");
  if (out_left != 0) return DataLoss(where + ": inflated size differs from the directory's");
  return Status::Ok();
}

std::string Deflate(std::string_view data) {
  z_stream stream{};
  deflateInit2(&stream, Z_DEFAULT_COMPRESSION, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY);
  std::string out(data.size() / 2 + 65536, '\0');  // grown below when needed
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  uint64_t in_left = data.size();
  size_t produced = 0;
  int rc = Z_OK;
  while (rc != Z_STREAM_END) {
    if (out.size() - produced < 65536) out.resize(out.size() * 2 + 65536);
    const uInt in_chunk = static_cast<uInt>(std::min<uint64_t>(in_left, 1u << 30));
    const uInt out_chunk = static_cast<uInt>(std::min<size_t>(out.size() - produced, 1u << 30));
    stream.avail_in = in_chunk;
    stream.next_out = reinterpret_cast<Bytef*>(out.data() + produced);
    stream.avail_out = out_chunk;
    rc = deflate(&stream, in_left == in_chunk ? Z_FINISH : Z_NO_FLUSH);
    in_left -= in_chunk - stream.avail_in;
    produced += out_chunk - stream.avail_out;
  }
  deflateEnd(&stream);
  out.resize(produced);
  return out;
}

}  // namespace

Result<std::vector<ZipEntry>> ListZip(std::string_view archive, const std::string& origin) {
  const size_t n = archive.size();
  if (n < 22)
    return DataLoss(origin + ": too short to be a zip/npz archive (" + std::to_string(n) +
                    " bytes)");
  // The end-of-central-directory record sits in the last 22 + 65535 bytes.
  size_t end = std::string_view::npos;
  const size_t lowest = n > 22 + 65535 ? n - 22 - 65535 : 0;
  for (size_t at = n - 22 + 1; at-- > lowest;) {
    if (Get32(archive, at) == kEndSig) {
      end = at;
      break;
    }
  }
  if (end == std::string_view::npos)
    return DataLoss(origin + ": no zip end-of-directory record (truncated or not an npz)");
  uint64_t entries = Get16(archive, end + 10);
  uint64_t dir_size = Get32(archive, end + 12);
  uint64_t dir_offset = Get32(archive, end + 16);
  if (end >= 20 && Get32(archive, end - 20) == kZip64LocatorSig) {
    const uint64_t record = Get64(archive, end - 20 + 8);
    if (record > n || n - record < 56 || Get32(archive, record) != kZip64EndSig) {
      return DataLoss(origin + ": broken zip64 end-of-directory record");
    }
    entries = Get64(archive, record + 32);
    dir_size = Get64(archive, record + 40);
    dir_offset = Get64(archive, record + 48);
  }
  if (dir_offset > n || dir_size > n - dir_offset)
    return DataLoss(origin + ": zip directory lies outside the file (truncated?)");
  if (entries > dir_size / 46)
    return DataLoss(origin + ": zip directory claims more entries than it holds");

  std::vector<ZipEntry> located;
  size_t at = static_cast<size_t>(dir_offset);
  const size_t dir_end = static_cast<size_t>(dir_offset + dir_size);
  for (uint64_t entry = 0; entry < entries; ++entry) {
    if (dir_end - at < 46 || Get32(archive, at) != kCentralSig) {
      return DataLoss(origin + ": zip directory entry " + std::to_string(entry) + " is damaged");
    }
    const uint16_t flags = Get16(archive, at + 8);
    const uint16_t method = Get16(archive, at + 10);
    const uint32_t crc = Get32(archive, at + 16);
    uint64_t csize = Get32(archive, at + 20);
    uint64_t usize = Get32(archive, at + 24);
    const size_t name_len = Get16(archive, at + 28);
    const size_t extra_len = Get16(archive, at + 30);
    const size_t comment_len = Get16(archive, at + 32);
    uint64_t local = Get32(archive, at + 42);
    if (dir_end - at - 46 < name_len + extra_len + comment_len) {
      return DataLoss(origin + ": zip directory entry " + std::to_string(entry) + " is truncated");
    }
    std::string name(archive.substr(at + 46, name_len));
    const std::string where = origin + ": member '" + name + "'";
    // ZIP64 extra field: 64-bit values for the 32-bit fields that are saturated.
    size_t extra = at + 46 + name_len;
    const size_t extra_end = extra + extra_len;
    while (extra + 4 <= extra_end) {
      const uint16_t id = Get16(archive, extra);
      const uint16_t len = Get16(archive, extra + 2);
      if (extra + 4 + len > extra_end) return DataLoss(where + ": damaged extra field");
      if (id == 0x0001) {
        size_t field = extra + 4;
        const size_t field_end = field + len;
        for (uint64_t* value : {&usize, &csize, &local}) {
          if (*value != k32Max) continue;
          if (field + 8 > field_end) return DataLoss(where + ": damaged zip64 field");
          *value = Get64(archive, field);
          field += 8;
        }
      }
      extra += 4u + len;
    }
    at = extra_end + comment_len;

    if (flags & 0x1) return DataLoss(where + ": encrypted zip members are not supported");
    if (local > n || n - local < 30 || Get32(archive, local) != kLocalSig) {
      return DataLoss(where + ": local header missing (truncated?)");
    }
    const uint64_t data_start =
        local + 30 + Get16(archive, local + 26) + Get16(archive, local + 28);
    if (data_start > n || csize > n - data_start) return DataLoss(where + ": data truncated");
    if (method == 0) {
      if (usize != csize) return DataLoss(where + ": stored member sizes disagree");
    } else if (method == 8) {
      if (usize > csize * kMaxDeflateRatio + 1024)
        return DataLoss(where + ": implausible uncompressed size");
    } else {
      return DataLoss(where + ": unsupported compression method " + std::to_string(method));
    }
    located.push_back(
        {std::move(name), method, crc, usize,
         archive.substr(static_cast<size_t>(data_start), static_cast<size_t>(csize))});
  }
  return located;
}

Result<std::string> ExtractZipEntry(const ZipEntry& entry, const std::string& origin) {
  const std::string where = origin + ": member '" + entry.name + "'";
  std::string data;
  if (entry.method == 0) {
    data = std::string(entry.payload);
  } else {
    MP_RETURN_IF_ERROR(Inflate(entry.payload, entry.size, &data, where));
  }
  MP_RETURN_IF_ERROR(CheckZipCrc(entry, data, origin));
  return data;
}

Status CheckZipCrc(const ZipEntry& entry, std::string_view data, const std::string& origin) {
  if (Crc32(data) != entry.crc)
    return DataLoss(origin + ": member '" + entry.name + "': CRC mismatch (corrupt data)");
  return Status::Ok();
}

Result<std::vector<ZipMember>> ReadZip(std::string_view archive, const std::string& origin,
                                       const MemberFilter& want) {
  MP_ASSIGN_OR_RETURN(std::vector<ZipEntry> all, ListZip(archive, origin));
  std::vector<ZipEntry> located;
  for (auto& entry : all) {
    if (!want || want(entry.name)) located.push_back(std::move(entry));
  }

  std::vector<ZipMember> members(located.size());
  std::vector<Status> errors(located.size());
  const auto count = static_cast<int64_t>(located.size());
#pragma omp parallel for schedule(dynamic) if (count > 1)
  for (int64_t k = 0; k < count; ++k) {
    const ZipEntry& entry = located[static_cast<size_t>(k)];
    ZipMember& member = members[static_cast<size_t>(k)];
    member.name = entry.name;
    auto data = ExtractZipEntry(entry, origin);
    if (data.ok()) {
      member.data = std::move(*data);
    } else {
      errors[static_cast<size_t>(k)] = data.status();
    }
  }
  for (const Status& error : errors) MP_RETURN_IF_ERROR(error);
  return members;
}

void ZipWriter::Add(const std::string& name, std::string data, bool deflate) {
  Entry entry;
  entry.name = name;
  entry.data = std::move(data);
  entry.deflate = deflate;
  entries_.push_back(std::move(entry));
}

std::string ZipWriter::Finish() {
  // Compress every member independently and in parallel.
  const auto count = static_cast<int64_t>(entries_.size());
#pragma omp parallel for schedule(dynamic)
  for (int64_t k = 0; k < count; ++k) {
    Entry& entry = entries_[static_cast<size_t>(k)];
    entry.crc = Crc32(entry.data);
    entry.size = entry.data.size();
    if (entry.deflate) {
      entry.data = Deflate(entry.data);
      entry.method = 8;
    }
    entry.compressed_size = entry.data.size();
  }
  std::string out;
  for (Entry& entry : entries_) {
    entry.offset = out.size();
    const bool zip64 = entry.size >= k32Max || entry.compressed_size >= k32Max;
    // Stored members start on a 64-byte boundary (padding in an extra field, id 0xD935 as zipalign
    // does), so that readers can use their arrays in place from a memory map.
    const size_t header = 30 + entry.name.size() + (zip64 ? 20 : 0);
    const uint16_t pad =
        entry.method == 0 ? static_cast<uint16_t>((64 - (entry.offset + header + 4) % 64) % 64) : 0;
    const uint16_t align_len = entry.method == 0 ? static_cast<uint16_t>(4 + pad) : 0;
    Put32(&out, kLocalSig);
    Put16(&out, zip64 ? 45 : 20);
    Put16(&out, 0);  // flags
    Put16(&out, entry.method);
    Put16(&out, 0);     // time 00:00
    Put16(&out, 0x21);  // date 1980-01-01: fixed so that the same content gives the same bytes
    Put32(&out, entry.crc);
    Put32(&out, zip64 ? k32Max : static_cast<uint32_t>(entry.compressed_size));
    Put32(&out, zip64 ? k32Max : static_cast<uint32_t>(entry.size));
    Put16(&out, static_cast<uint16_t>(entry.name.size()));
    Put16(&out, static_cast<uint16_t>((zip64 ? 20 : 0) + align_len));
    out += entry.name;
    if (zip64) {
      Put16(&out, 0x0001);
      Put16(&out, 16);
      Put64(&out, entry.size);
      Put64(&out, entry.compressed_size);
    }
    if (align_len) {
      Put16(&out, 0xD935);
      Put16(&out, pad);
      out.append(pad, '\0');
    }
    out += entry.data;
    std::string().swap(entry.data);
  }
  const uint64_t dir_offset = out.size();
  for (const Entry& entry : entries_) {
    const bool big_sizes = entry.size >= k32Max || entry.compressed_size >= k32Max;
    const bool big_offset = entry.offset >= k32Max;
    const uint16_t extra_len = static_cast<uint16_t>((big_sizes ? 16 : 0) + (big_offset ? 8 : 0));
    Put32(&out, kCentralSig);
    Put16(&out, 45);  // made by: spec 4.5
    Put16(&out, (big_sizes || big_offset) ? 45 : 20);
    Put16(&out, 0);
    Put16(&out, entry.method);
    Put16(&out, 0);
    Put16(&out, 0x21);
    Put32(&out, entry.crc);
    Put32(&out, big_sizes ? k32Max : static_cast<uint32_t>(entry.compressed_size));
    Put32(&out, big_sizes ? k32Max : static_cast<uint32_t>(entry.size));
    Put16(&out, static_cast<uint16_t>(entry.name.size()));
    Put16(&out, extra_len ? static_cast<uint16_t>(extra_len + 4) : 0);
    Put16(&out, 0);            // comment
    Put16(&out, 0);            // disk
    Put16(&out, 0);            // internal attributes
    Put32(&out, 0x81A40000u);  // external attributes: regular file, 0644
    Put32(&out, big_offset ? k32Max : static_cast<uint32_t>(entry.offset));
    out += entry.name;
    if (extra_len) {
      Put16(&out, 0x0001);
      Put16(&out, extra_len);
      if (big_sizes) {
        Put64(&out, entry.size);
        Put64(&out, entry.compressed_size);
      }
      if (big_offset) Put64(&out, entry.offset);
    }
  }
  const uint64_t dir_size = out.size() - dir_offset;
  const bool zip64 = entries_.size() >= 0xFFFF || dir_offset >= k32Max || dir_size >= k32Max;
  if (zip64) {
    const uint64_t record = out.size();
    Put32(&out, kZip64EndSig);
    Put64(&out, 44);
    Put16(&out, 45);
    Put16(&out, 45);
    Put32(&out, 0);
    Put32(&out, 0);
    Put64(&out, entries_.size());
    Put64(&out, entries_.size());
    Put64(&out, dir_size);
    Put64(&out, dir_offset);
    Put32(&out, kZip64LocatorSig);
    Put32(&out, 0);
    Put64(&out, record);
    Put32(&out, 1);
  }
  Put32(&out, kEndSig);
  Put16(&out, 0);
  Put16(&out, 0);
  const uint16_t count16 = zip64 ? 0xFFFF : static_cast<uint16_t>(entries_.size());
  Put16(&out, count16);
  Put16(&out, count16);
  Put32(&out, zip64 ? k32Max : static_cast<uint32_t>(dir_size));
  Put32(&out, zip64 ? k32Max : static_cast<uint32_t>(dir_offset));
  Put16(&out, 0);
  entries_.clear();
  return out;
}

}  // namespace motionpipe

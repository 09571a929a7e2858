# Writes OUTPUT as a header defining `kBuiltinPapers`: {file name, contents} of every DIR/*.yaml,
# sorted by name (the papers' tables, read by the report).
file(GLOB FILES ${DIR}/*.yaml)
list(SORT FILES)
set(DELIM "mp_embed_")
set(TEXT "// Generated from ${DIR}/*.yaml; do not edit.\n#pragma once\n#include <utility>\n")
string(APPEND TEXT "inline constexpr std::pair<const char*, const char*> kBuiltinPapers[] = {\n")
foreach(FILE ${FILES})
  get_filename_component(NAME ${FILE} NAME)
  file(READ ${FILE} CONTENT)
  string(APPEND TEXT "    {\"${NAME}\", R\"${DELIM}(${CONTENT})${DELIM}\"},\n")
endforeach()
string(APPEND TEXT "};\n")
file(WRITE ${OUTPUT} "${TEXT}")

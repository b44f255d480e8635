/* fte_fmi2.h -- the FMI 2.0 C interface (types, callbacks, common and co-simulation functions) as
 * the FMI 2.0 standard defines it, platform "default"; written for fte_casadi's FMUs.
 * Define FMI2_FUNCTION_PREFIX (e.g. MyModel_) to prefix every function name, as for a source-code
 * FMU compiled into a static library; without it the functions are exported unprefixed. */
#ifndef FTE_FMI2_H
#define FTE_FMI2_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define fmi2TypesPlatform "default"
#define fmi2Version "2.0"

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;

#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment componentEnvironment, fmi2String instanceName,
                                   fmi2Status status, fmi2String category, fmi2String message, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t nobj, size_t size);
typedef void (*fmi2CallbackFreeMemory)(void *obj);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment componentEnvironment, fmi2Status status);

typedef struct {
  fmi2CallbackLogger logger;
  fmi2CallbackAllocateMemory allocateMemory;
  fmi2CallbackFreeMemory freeMemory;
  fmi2StepFinished stepFinished;
  fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#ifdef FMI2_FUNCTION_PREFIX
#define FTE_FMI2_PASTE(a, b) a##b
#define FTE_FMI2_JOIN(a, b) FTE_FMI2_PASTE(a, b)
#define FTE_FMI2_NAME(name) FTE_FMI2_JOIN(FMI2_FUNCTION_PREFIX, name)
#define FTE_FMI2_EXPORT
#else
#define FTE_FMI2_NAME(name) name
#if defined _WIN32 || defined __CYGWIN__
#define FTE_FMI2_EXPORT __declspec(dllexport)
#elif defined __GNUC__ && __GNUC__ >= 4
#define FTE_FMI2_EXPORT __attribute__((visibility("default")))
#else
#define FTE_FMI2_EXPORT
#endif
#endif

#define fmi2GetTypesPlatform FTE_FMI2_NAME(fmi2GetTypesPlatform)
#define fmi2GetVersion FTE_FMI2_NAME(fmi2GetVersion)
#define fmi2SetDebugLogging FTE_FMI2_NAME(fmi2SetDebugLogging)
#define fmi2Instantiate FTE_FMI2_NAME(fmi2Instantiate)
#define fmi2FreeInstance FTE_FMI2_NAME(fmi2FreeInstance)
#define fmi2SetupExperiment FTE_FMI2_NAME(fmi2SetupExperiment)
#define fmi2EnterInitializationMode FTE_FMI2_NAME(fmi2EnterInitializationMode)
#define fmi2ExitInitializationMode FTE_FMI2_NAME(fmi2ExitInitializationMode)
#define fmi2Terminate FTE_FMI2_NAME(fmi2Terminate)
#define fmi2Reset FTE_FMI2_NAME(fmi2Reset)
#define fmi2GetReal FTE_FMI2_NAME(fmi2GetReal)
#define fmi2GetInteger FTE_FMI2_NAME(fmi2GetInteger)
#define fmi2GetBoolean FTE_FMI2_NAME(fmi2GetBoolean)
#define fmi2GetString FTE_FMI2_NAME(fmi2GetString)
#define fmi2SetReal FTE_FMI2_NAME(fmi2SetReal)
#define fmi2SetInteger FTE_FMI2_NAME(fmi2SetInteger)
#define fmi2SetBoolean FTE_FMI2_NAME(fmi2SetBoolean)
#define fmi2SetString FTE_FMI2_NAME(fmi2SetString)
#define fmi2GetFMUstate FTE_FMI2_NAME(fmi2GetFMUstate)
#define fmi2SetFMUstate FTE_FMI2_NAME(fmi2SetFMUstate)
#define fmi2FreeFMUstate FTE_FMI2_NAME(fmi2FreeFMUstate)
#define fmi2SerializedFMUstateSize FTE_FMI2_NAME(fmi2SerializedFMUstateSize)
#define fmi2SerializeFMUstate FTE_FMI2_NAME(fmi2SerializeFMUstate)
#define fmi2DeSerializeFMUstate FTE_FMI2_NAME(fmi2DeSerializeFMUstate)
#define fmi2GetDirectionalDerivative FTE_FMI2_NAME(fmi2GetDirectionalDerivative)
#define fmi2SetRealInputDerivatives FTE_FMI2_NAME(fmi2SetRealInputDerivatives)
#define fmi2GetRealOutputDerivatives FTE_FMI2_NAME(fmi2GetRealOutputDerivatives)
#define fmi2DoStep FTE_FMI2_NAME(fmi2DoStep)
#define fmi2CancelStep FTE_FMI2_NAME(fmi2CancelStep)
#define fmi2GetStatus FTE_FMI2_NAME(fmi2GetStatus)
#define fmi2GetRealStatus FTE_FMI2_NAME(fmi2GetRealStatus)
#define fmi2GetIntegerStatus FTE_FMI2_NAME(fmi2GetIntegerStatus)
#define fmi2GetBooleanStatus FTE_FMI2_NAME(fmi2GetBooleanStatus)
#define fmi2GetStringStatus FTE_FMI2_NAME(fmi2GetStringStatus)

typedef const fmi2ValueReference fmi2VR; /* shorthand of this header only */

FTE_FMI2_EXPORT const char *fmi2GetTypesPlatform(void);
FTE_FMI2_EXPORT const char *fmi2GetVersion(void);
FTE_FMI2_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                               const fmi2String categories[]);
FTE_FMI2_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                              fmi2String fmuResourceLocation,
                                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                              fmi2Boolean loggingOn);
FTE_FMI2_EXPORT void fmi2FreeInstance(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                                               fmi2Real tolerance, fmi2Real startTime,
                                               fmi2Boolean stopTimeDefined, fmi2Real stopTime);
FTE_FMI2_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2Terminate(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2Reset(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2GetReal(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2Integer value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2Boolean value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetString(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2String value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetReal(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2Integer value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2Boolean value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetString(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2String value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size);
FTE_FMI2_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                                 fmi2Byte serializedState[], size_t size);
FTE_FMI2_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                                   size_t size, fmi2FMUstate *FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, fmi2VR vUnknown_ref[], size_t nUnknown,
                                                        fmi2VR vKnown_ref[], size_t nKnown,
                                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, fmi2VR vr[], size_t nvr,
                                                       const fmi2Integer order[], const fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, fmi2VR vr[], size_t nvr,
                                                        const fmi2Integer order[], fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                      fmi2Real communicationStepSize,
                                      fmi2Boolean noSetFMUStatePriorToCurrentPoint);
FTE_FMI2_EXPORT fmi2Status fmi2CancelStep(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* FTE_FMI2_H */
